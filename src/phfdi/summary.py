"""Loop performance figures of a run, per setpoint segment, for humans and JSON."""

from __future__ import annotations

import numpy as np

from .records.record import Record

SETTLE_BAND_PH = 0.1


def _segments(run: Record) -> list[tuple[float, float, float]]:
    """(start_s, end_s, setpoint) for each stretch of constant pH setpoint."""
    t, sp = run.time_s, run["ph_setpoint"]
    if np.all(np.isnan(sp)):
        return []
    edges = [0] + [i for i in range(1, len(sp)) if sp[i] != sp[i - 1]] + [len(sp)]
    return [(float(t[a]), float(t[b - 1]), float(sp[b - 1])) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def segment_stats(run: Record, start_s: float, end_s: float, setpoint: float) -> dict:
    t = run.time_s
    m = (t >= start_s) & (t <= end_s)
    err = run["ph_true"][m] - setpoint
    tt = t[m]
    outside = np.nonzero(np.abs(err) > SETTLE_BAND_PH)[0]
    if len(outside) == 0:
        settle = 0.0
    elif outside[-1] == len(err) - 1:
        settle = None  # never settles within the segment
    else:
        settle = float(tt[outside[-1] + 1] - start_s)
    tail = err[len(err) // 2:]
    return {
        "start_s": start_s,
        "end_s": end_s,
        "setpoint_ph": setpoint,
        "settling_time_s": settle,
        "iae_ph_s": float(np.sum(np.abs(err)) * run.dt_s),
        "max_abs_error_ph": float(np.max(np.abs(err))),
        "second_half_std_ph": float(np.std(tail)),
        "second_half_mean_error_ph": float(np.mean(tail)),
    }


def valve_reversals(position: np.ndarray, threshold_pct: float = 0.05) -> int:
    """Direction changes of the stem larger than a small threshold."""
    d = np.diff(position)
    d = d[np.abs(d) > threshold_pct]
    return int(np.sum(np.diff(np.sign(d)) != 0)) if len(d) > 1 else 0


def summarize(run: Record) -> dict:
    faults = run.metadata.get("faults", [])
    out = {
        "scenario": run.metadata.get("scenario"),
        "faults": [{k: f[k] for k in ("type", "where", "params", "onset_s", "ramp_s") if k in f} for f in faults],
        "duration_s": float(run.time_s[-1] - run.time_s[0]),
        "samples": len(run),
        "segments": [segment_stats(run, *s) for s in _segments(run)],
        "valve_travel_pct": float(np.sum(np.abs(np.diff(run["valve_position_pct"])))),
        "valve_reversals": valve_reversals(run["valve_position_pct"]),
    }
    if faults:
        onset = min(f["onset_s"] for f in faults)
        t = run.time_s
        before = (t >= onset - 1000) & (t < onset)
        after = t >= onset
        e = run["ph_true"] - run["ph_setpoint"]
        out["fault_onset_s"] = onset
        out["ph_error_std_before_onset"] = float(np.std(e[before])) if before.any() else None
        out["ph_error_std_after_onset"] = float(np.std(e[after])) if after.any() else None
        out["ph_mean_error_after_onset"] = float(np.mean(e[after])) if after.any() else None
    return out


def format_summary(s: dict) -> str:
    lines = [f"scenario {s['scenario']}: {s['duration_s']:.0f} s, {s['samples']} samples"]
    if s["faults"]:
        for f in s["faults"]:
            lines.append(f"  fault: {f['type']} on {f['where']} {f['params']} from {f['onset_s']:g} s")
    else:
        lines.append("  fault: none (healthy)")
    for seg in s["segments"]:
        settle = "never" if seg["settling_time_s"] is None else f"{seg['settling_time_s']:.0f} s"
        lines.append(
            f"  pH {seg['setpoint_ph']:g} from {seg['start_s']:.0f} s: settles (+-{SETTLE_BAND_PH}) in {settle}, "
            f"max |error| {seg['max_abs_error_ph']:.3f}, IAE {seg['iae_ph_s']:.1f} pH.s, "
            f"2nd-half std {seg['second_half_std_ph']:.4f}")
    lines.append(f"  valve: travel {s['valve_travel_pct']:.1f} % of span, {s['valve_reversals']} reversals")
    if s.get("ph_error_std_before_onset") is not None and s.get("ph_error_std_after_onset") is not None:
        lines.append(f"  pH error std: {s['ph_error_std_before_onset']:.4f} in the 1000 s before the onset, "
                     f"{s['ph_error_std_after_onset']:.4f} after (mean {s['ph_mean_error_after_onset']:+.3f})")
    return "\n".join(lines)
