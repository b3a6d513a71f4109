"""/fault_alarm messages as plain dicts: from a bag or a live subscription, one line per alarm (no rclpy).

Works on rclpy messages and on rosbags' decoded ones alike (same field names).
"""

from __future__ import annotations

import math

from phfdi_base.stamps import ns_to_seconds

STATE_NAMES = {0: "OK", 1: "WARN", 2: "ALARM"}


def exceedance(value: float, threshold: float, relation: str = ">") -> str:
    """``"value > threshold"`` with as many decimals as it takes to show the difference (one decimal printed
    an alarm at 5.04 over 5.0 as "5.0 > 5.0").

    >>> exceedance(15.12, 5.0), exceedance(5.04, 5.0), exceedance(5.0004, 5.0, "> threshold")
    ('15.1 > 5.0', '5.04 > 5.00', '5.0004 > threshold 5.0000')
    """
    for decimals in range(1, 7):
        shown_value, shown_threshold = f"{value:.{decimals}f}", f"{threshold:.{decimals}f}"
        if shown_value != shown_threshold:
            break
    return f"{shown_value} {relation} {shown_threshold}"


def severity_of(summary: dict) -> tuple[float, str]:
    """An alarm's severity as /fault_alarm carries it: the fault's parameter once isolation named the
    fault (e.g. backlash width, % of span), before that the RMS pH residual from onset to detection."""
    p = summary.get("parameter")
    if p and summary["fault_class"] not in ("pending", "unknown"):
        return float(p["value"]), f"{p['unit']} ({p['name']})"
    return float(summary["severity"]), "pH (RMS residual, onset to detection)"


def from_summaries(alarms: list[dict]) -> list[dict]:
    """Alarm summaries, as the detector nodes report them (the physics detector's ``Alarm.summary()``, the
    multichannel detector's alarms with their naming under ``isolation``), in the shape of :func:`per_alarm`."""
    out = []
    for a in alarms:
        if "fault_class" not in a:  # the multichannel detector's: named (or not yet) under "isolation"
            iso = a.get("isolation") or {}
            a = {**a, "fault_class": iso.get("fault_class", "pending"), "confidence": iso.get("confidence", 0.0)}
            # as its node publishes them: the namer's size and unit once named
            severity, unit = (float(iso["size"]), str(iso["unit"])) if iso else (math.nan, "")
        else:
            severity, unit = severity_of(a)
        if not math.isfinite(severity):
            unit = ""
        out.append({"onset_time": a["onset_time"], "detection_time": a["detection_time"],
                    "fault_class": a["fault_class"], "confidence": a["confidence"], "severity": severity,
                    "severity_unit": unit, "cleared": a.get("cleared_time")})
    return out


def _seconds(t) -> float:
    return ns_to_seconds(t.sec, t.nanosec)


def to_dict(msg) -> dict:
    """One phfdi_interfaces/FaultAlarm message; times in s of simulated time (None while OK)."""
    detection = _seconds(msg.detection_time)
    return {
        "time": _seconds(msg.stamp), "loop": msg.loop, "state": STATE_NAMES.get(int(msg.state), str(msg.state)),
        "fault_class": msg.fault_class, "confidence": float(msg.confidence),
        "onset_time": _seconds(msg.onset_time) if detection > 0 else None,
        "detection_time": detection if detection > 0 else None,
        "severity": float(msg.severity), "severity_unit": msg.severity_unit,
        "statistic": float(msg.statistic), "threshold": float(msg.threshold),
        "statistic_name": getattr(msg, "statistic_name", ""),  # a bag recorded before the field: none
        "wavelet_level": int(msg.wavelet_level), "message": msg.message,
    }


def per_alarm(messages: list[dict]) -> list[dict]:
    """The latest message about each alarm (keyed by detection time): its final diagnosis,
    with ``cleared`` set when a later message of that alarm says so."""
    out: dict[float, dict] = {}
    for m in messages:
        if m["detection_time"] is None:
            continue
        key = round(m["detection_time"], 6)
        previous = out.get(key)
        cleared = previous.get("cleared") if previous else None
        out[key] = dict(m, cleared=cleared if m["state"] != "OK" else m["time"])
    return [out[k] for k in sorted(out)]


def format_table(alarms: list[dict]) -> str:
    """One line per alarm: onset, detection, class, confidence, severity."""
    if not alarms:
        return "  no alarm"
    lines = [f"  {'onset (s)':>10s} {'detected (s)':>12s}  {'class':12s} {'confidence':>10s}  severity"]
    for a in alarms:
        sev = "-" if a["severity"] is None or not math.isfinite(a["severity"]) else f"{a['severity']:.3g}"
        lines.append(f"  {a['onset_time']:10.0f} {a['detection_time']:12.0f}  {a['fault_class']:12s} "
                     f"{a['confidence']:10.2f}  {sev} {a['severity_unit']}"
                     + (f"; cleared {a['cleared']:g} s" if a.get("cleared") is not None else ""))
    return "\n".join(lines)
