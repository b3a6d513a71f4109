"""Simulated time on the wire: stamps as whole nanoseconds, one set of conversions for every package.

The stamp of sample k is exactly ``k * sample_period_ns(sample_time_s)``
nanoseconds; a ROS ``builtin_interfaces/Time`` is that number split into
``sec`` and ``nanosec``. No rclpy here: the bag tools use these too.

Examples
--------
>>> dt_ns = sample_period_ns(0.5)
>>> split_ns(3 * dt_ns)
(1, 500000000)
>>> join_ns(1, 500000000) // dt_ns
3
>>> seconds_to_ns(1.25), ns_to_seconds(1, 250000000)
(1250000000, 1.25)
>>> time_on_grid_s(3 * dt_ns, dt_ns, 0.5), time_on_grid_s(3 * dt_ns + 1, dt_ns, 0.5)
(1.5, 1.500000001)
"""

from __future__ import annotations

import math

__all__ = ["NS_PER_S", "finite_or", "join_ns", "ns_to_seconds", "record_stamps_ns", "sample_index", "sample_period_ns",
           "seconds_to_ns", "split_ns", "stamp_seconds", "stamps_seconds", "time_ns", "time_on_grid_s",
           "times_on_grid_s"]

NS_PER_S = 1_000_000_000


def sample_period_ns(sample_time_s: float) -> int:
    """The sample time as whole nanoseconds (stamps are exact multiples of it)."""
    dt_ns = round(sample_time_s * 1e9)
    if dt_ns <= 0 or abs(dt_ns - sample_time_s * 1e9) > 1e-3:
        raise ValueError(f"sample_time_s = {sample_time_s} s is not a whole number of nanoseconds")
    return dt_ns


def split_ns(ns: int) -> tuple[int, int]:
    """Nanoseconds -> (sec, nanosec) of a ROS time."""
    return divmod(ns, NS_PER_S)


def join_ns(sec: int, nanosec: int) -> int:
    """(sec, nanosec) of a ROS time -> nanoseconds."""
    return sec * NS_PER_S + nanosec


def valid_stamp(sec: int, nanosec: int) -> bool:
    """A stamp that can be a sample's: seconds not negative, nanoseconds below 1e9 (joined, any other reads as a
    clock that jumped).

    >>> valid_stamp(3, 0), valid_stamp(-1, 0), valid_stamp(3, NS_PER_S)
    (True, False, False)
    """
    return sec >= 0 and 0 <= nanosec < NS_PER_S


def time_ns(stamp) -> int:
    """Nanoseconds of a ROS time, or of anything with ``sec`` and ``nanosec`` (a bag's decoded stamp)."""
    return join_ns(stamp.sec, stamp.nanosec)


def seconds_to_ns(t_s: float) -> int:
    """Seconds -> whole nanoseconds, rounded, never negative."""
    return max(0, round(t_s * 1e9))


def ns_to_seconds(sec: int, nanosec: int) -> float:
    """(sec, nanosec) of a ROS time -> seconds (float)."""
    return sec + nanosec * 1e-9


def sample_index(ns: int, dt_ns: int) -> int | None:
    """Index of the sample stamped ``ns``; None if the stamp is not on the sample grid."""
    k, rest = divmod(ns, dt_ns)
    return None if rest else k


def finite_or(t_s: float, fallback_ns: int) -> int:
    """Nanoseconds of ``t_s``, or ``fallback_ns`` when it is not finite."""
    return seconds_to_ns(t_s) if math.isfinite(t_s) else fallback_ns


def time_on_grid_s(ns: int, dt_ns: int, dt_s: float) -> float:
    """Time (s) of the sample stamped ``ns``: ``k * dt_s`` exactly as the simulation computes it when the
    stamp is on the sample grid, else the stamp itself in seconds. The one rule for the live detector and
    for reading a bag back (:func:`times_on_grid_s`), so both see the same floats."""
    return (ns // dt_ns) * dt_s if ns % dt_ns == 0 else ns * 1e-9


def times_on_grid_s(stamps: list[int], dt_s) -> list[float]:
    """Times (s) of a recording's stamps by :func:`time_on_grid_s` when ``dt_s`` is a usable sample time and
    every stamp is on its grid; else every stamp in seconds (a recording off the grid is not forced onto it).

    Examples
    --------
    >>> times_on_grid_s([0, 500_000_000, 1_000_000_000], 0.5)
    [0.0, 0.5, 1.0]
    >>> times_on_grid_s([0, 250_000_000], 0.5), times_on_grid_s([0, 1], None)
    ([0.0, 0.25], [0.0, 1e-09])
    """
    try:
        dt_ns = sample_period_ns(float(dt_s)) if dt_s else None
    except (TypeError, ValueError, OverflowError):
        dt_ns = None
    if dt_ns and all(ns % dt_ns == 0 for ns in stamps):
        return [time_on_grid_s(ns, dt_ns, dt_s) for ns in stamps]
    return [ns * 1e-9 for ns in stamps]


# ---- measured records (phfdi bag from-csv, the learned node) ---------------------------------------------
def record_stamps_ns(time_s):
    """Stamps (ns, int64 array) of a measured record's rows: its own time rounded to the nanosecond, what
    ``phfdi bag from-csv`` writes and :func:`stamps_seconds` turns back into the detector's seconds.

    Examples
    --------
    >>> record_stamps_ns([1.25200000000041, 1.60399999999936]).tolist()
    [1252000000, 1604000000]
    """
    import numpy as np

    return np.round(np.asarray(time_s, dtype=float) * 1e9).astype(np.int64)


def stamp_seconds(ns: int) -> float:
    """Seconds of a measured record's stamp: ``ns / 1e9`` correctly rounded (the decimal time to the ns, as
    written). The one rule for the learned detector node (each message) and the offline replay of a record
    (:func:`stamps_seconds`): both give the detector the same floats.

    Examples
    --------
    >>> stamp_seconds(1_000_013), ns_to_seconds(0, 1_000_013)  # the sum of two roundings can miss it
    (0.001000013, 0.0010000130000000001)
    """
    return ns / NS_PER_S


def stamps_seconds(ns):
    """:func:`stamp_seconds` of every stamp (a float array).

    Examples
    --------
    >>> stamps_seconds(record_stamps_ns([1.25200000000041, 505.798999999999])).tolist()
    [1.252, 505.799]
    """
    import numpy as np

    ns = np.asarray(ns, dtype=np.int64)
    if ns.size and int(np.abs(ns).max()) >= 2 ** 53:  # not exact as float64: Python's int division, per stamp
        return np.array([stamp_seconds(int(v)) for v in ns])
    return ns / NS_PER_S  # exact operands, one correctly rounded division: the floats of stamp_seconds
