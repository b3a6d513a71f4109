"""Alarms as lines for people: the multichannel detector's (``LearnedDetector`` alarm dicts: the channels and bands
behind each, and with a confirming reference its verdict, fault alarm or deviation outside calibration). ``phfdi
replay``, ``phfdi demo`` and the live replay print these."""

from __future__ import annotations

from typing import Sequence

from wavelet_fdi.alarm_messages import exceedance


def format_alarms(alarms: Sequence[dict], unit_of_time: str = "s") -> str:
    """Each alarm for people: where it was detected, the channels behind it, its name, verdict and when it
    cleared."""
    lines = ["no alarm"] if not alarms else []
    for a in alarms:
        lines += _alarm_lines(a, unit_of_time)
    return "\n".join(lines)


def _alarm_lines(a: dict, u: str) -> list[str]:
    top = ", ".join(f"{c} {v['share']:.0%} ({max(v['bands'], key=v['bands'].get)})"
                    for c, v in list(a["contributions"].items())[:4])
    # the file's own position (line of a text file, row of Parquet, sample of a bag; 1 = the first), never
    # the detector's 0-based index: a spreadsheet or editor shows the same number
    where = f"{a.get('where', 'line')} {a['detection_line']}" if "detection_line" in a \
        else f"sample {a['detection_index'] + 1}"
    where = ", ".join(filter(None, [a.get("detection_stamp"), where]))
    onset = "" if a.get("onset_time") is None else f", onset about {a['onset_time']:g} {u}"
    if a.get("onset_stamp"):
        onset += f" ({a['onset_stamp']})"
    crossing = f"{a['statistic']} ({exceedance(a['statistic_value'], a['threshold'])})"
    verdict = a.get("verdict")
    iso = a.get("isolation") or {}
    if verdict is None:  # a reference that does not confirm: every crossing is an alarm
        out = [f"alarm {a['alarm_id']}: detected {a['detection_time']:g} {u} ({where}){onset}, by {crossing}"]
    elif verdict == "fault":
        out = [f"alarm {a['alarm_id']}: fault confirmed {a['confirmed_time']:g} {u}; deviation detected "
               f"{a['detection_time']:g} {u} ({where}){onset}, by {crossing}"]
    else:
        said = "" if a.get("announced", True) else " (not announced: within the hold of the last one)"
        out = [f"deviation {a['alarm_id']}: detected {a['detection_time']:g} {u} ({where}){onset}, by {crossing}; "
               f"{verdict or 'being checked'}{said}"]
    out.append(f"  channels: {top}")
    if a.get("outside_healthy_range"):
        out.append(f"  beyond the reference's healthy runs then: {', '.join(a['outside_healthy_range'])} (a fault, "
                   f"or an operation the calibration never saw)")
    if iso:
        out += _named_lines(iso, verdict, u)
    looked = [lk["after_samples"] for lk in a.get("looks") or [] if not lk.get("confirmed")]
    if looked:  # a deviation still up was looked at again with the rows after it: not confirmed then either
        out.append(f"  looked at again {', '.join(map(str, looked))} samples after the detection: not confirmed")
    if a.get("cleared_time") is not None:
        ep = a.get("episode_contributions") or {}
        stamp = f" ({a['cleared_stamp']})" if a.get("cleared_stamp") else ""
        out.append(f"  cleared {a['cleared_time']:g} {u}{stamp}; over the episode: "
                   + ", ".join(f"{c} {v['share']:.0%}" for c, v in list(ep.items())[:4]))
    return out


#: the confirmation's statistics as a report names them (wavelet_fdi.estimator_isolation)
_STATISTIC_WORDS = {"change": "over the window", "jump": "at its start"}


def _statistic_words(name: str) -> str:
    """A confirmation statistic as a report names it; ``change@N``: a later look's change (its window kept N
    samples after the detection)."""
    if name.startswith("change@"):
        return f"over the window to {name[7:]} samples after the detection"
    return _STATISTIC_WORDS.get(name, name)


def _named_lines(iso: dict, verdict: str | None, u: str) -> list[str]:
    began = "" if iso.get("start_time") is None else f" from about {iso['start_time']:g} {u}"
    size = f"{iso['size']:g} {iso['unit']}".strip()
    conf = iso.get("confirmation") or {}
    # each statistic against its margin: the change over the window, the jump at its start (an offset's)
    change = ", ".join(f"{_statistic_words(k)} "
                       f"{exceedance(v, conf['thresholds'][k], '>' if v > conf['thresholds'][k] else '<=')}"
                       for k, v in (conf.get("statistics") or {}).items() if k in conf.get("thresholds", {}))
    if verdict == "outside calibration":
        why = ("no healthy re-adaptation fits either" if iso["fault_class"] == "unexplained"
               else f"best explained as healthy operation re-adapted: {iso['description']} ({size})")
        return [f"  outside calibration, not a fault: the innovations' change against the run's own past: {change} "
                f"(the margins); {why}"]
    # each namer says how sure it is its own way: the estimator's log-likelihood gain over healthy, the physics
    # kind's isolation its class's likelihood share
    how = (f"log-likelihood gain {iso['log_likelihood_gain']:.0f} over healthy" if "log_likelihood_gain" in iso
           else f"confidence {iso['confidence']:.2f}" if "confidence" in iso else "")
    if iso["family"] == "none" and verdict is None:  # a namer that does not confirm found no fault to name
        return [f"  not named: {iso['description']}"]
    out = [f"  named: {iso['family']} fault, {iso['description']} ({size}{began}" + (f"; {how})" if how else ")")]
    against = iso.get("against_feed")
    if against:  # confirmed by the feed check (wavelet_fdi.feed_checks), not by the innovations' change
        feed = "acid" if against["feed_direction"] < 0 else "base"
        out.append(f"  confirmed: the reading moved against the only feed that ran ({feed}) from "
                   f"{against['first_time']:g} {u}: t = {against['t']:g} > {against['level']:g} (the level a "
                   f"reading about a pH the {feed} moves its own way passes with the stated probability per sample)"
                   + ("; the size is the reading's own rate in that window, a lower bound"
                      if iso.get("size_is_lower_bound") else ""))
        return out
    if change:
        out.append(f"  confirmed: the innovations' change against the run's own past: {change} (the margins), and "
                   f"the probe fault fits better than any feed's re-adapted strength")
    return out
