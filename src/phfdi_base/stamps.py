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
"""

from __future__ import annotations

import math

__all__ = ["NS_PER_S", "finite_or", "join_ns", "ns_to_seconds", "sample_index", "sample_period_ns", "seconds_to_ns", "split_ns"]

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
