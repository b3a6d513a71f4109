"""Sensor effects as blocks (see :mod:`phfdi_base.blocks`), stepped once per sample.

A sensor is a :class:`~phfdi_base.blocks.Chain` of these, applied to the true
value: for example transport delay, then first-order probe lag, then noise.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from phfdi_base.blocks import register_block
from phfdi_base.faults import Fault, FaultParam, Injection, Range, SizeRange, register_fault


def _check(name: str, value: float, positive: bool = False) -> None:
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise ValueError(f"{name} must be {'positive' if positive else 'non-negative'} and finite, got {value}")


def lag_step(y: float | None, x: float, tau_s: float, dt_s: float) -> float:
    """One sample of a first-order lag, exact for ``x`` held over the sample of ``dt_s``.

    No state yet (``y`` None) or no lag (``tau_s`` <= 0): the output is ``x``.
    """
    if y is None or tau_s <= 0.0:
        return x
    return y + (1.0 - math.exp(-dt_s / tau_s)) * (x - y)


@register_block("sensor_delay", fault=Fault(
    "probe_delay", site="ph_sensor", description="pH probe transport delay of 10 s (paper Fig. 16-17)",
    # the diagnosis fits from no delay up to 600 s (and a fifth of the record)
    params=(FaultParam("delay_s", "s", (0.0, math.inf), paper=10.0, search=Range(1.0, 120.0, log=True),
                       diagnosis=Range(0.0, 600.0)),),
    severities=(5.0, 10.0, 20.0)))
@dataclass
class TransportDelay:
    """Pure transport delay: y(t) = x(t - delay_s).

    Delays that are not a multiple of the sample time interpolate linearly
    between the two neighbouring samples. Before enough history exists the
    output holds the first input (the loop starts at rest). With severity s
    the delay is s * delay_s.
    """

    delay_s: float
    dt_s: float = 1.0
    severity: float = 1.0
    _buf: deque = field(default_factory=deque, repr=False)

    def __post_init__(self) -> None:
        _check("delay_s", self.delay_s)
        _check("dt_s", self.dt_s, positive=True)
        self._n = int(math.ceil(self.delay_s / self.dt_s - 1e-12)) + 1

    def reset(self, x0: float) -> None:
        self._buf = deque([x0] * (self._n + 1), maxlen=self._n + 1)

    def step(self, x: float, t_s: float) -> float:
        if not self._buf:
            self.reset(x)
        self._buf.append(x)
        lag = self.severity * self.delay_s / self.dt_s  # in samples
        k = int(lag)
        frac = lag - k
        newest = len(self._buf) - 1
        y = self._buf[newest - k]
        if frac > 1e-12:
            y = (1.0 - frac) * y + frac * self._buf[newest - k - 1]
        return y

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """:meth:`step` for each sample of ``x`` in turn (the same arithmetic, vectorised)."""
        x = np.asarray(x, dtype=float)
        if len(x) == 0:
            return x.copy()
        if not self._buf:
            self.reset(float(x[0]))
        hist = np.fromiter(self._buf, dtype=float, count=len(self._buf))
        both = np.concatenate([hist, x])
        lag = self.severity * self.delay_s / self.dt_s
        k = int(lag)
        frac = lag - k
        newest = len(hist) + np.arange(len(x))  # where sample j sits once appended
        y = both[newest - k]
        if frac > 1e-12:
            y = (1.0 - frac) * y + frac * both[newest - k - 1]
        keep = self._n + 1  # the buffer's length, as reset makes it
        self._buf = deque(both[-keep:].tolist(), maxlen=keep)
        return y


#: How ``phfdi inject`` hides each probe fault in a measured record (``inject=``): the size ranges are where a size
#: still means the fault: beyond the probe's 0..14 pH span a bias, a drift per minute or a noise's standard deviation
#: only clips to the span's ends; a lag longer than a day is a frozen probe in any record; a gain at or below -1
#: turns the slope over. The rig estimator's classes: a slope error is locally an offset or a drift, a drift over a
#: short window an offset; a frozen or sluggish reading loses its noise (its class is the noise's, s < 1).
PH_SPAN = SizeRange(-14.0, 14.0)


@register_block("sensor_lag", fault=Fault(
    "probe_lag", site="ph_sensor", description="first-order pH probe lag (a diagnosis candidate)",
    # the diagnosis fits up to 600 s (and a fifth of the record)
    params=(FaultParam("tau_s", "s", (0.0, math.inf), search=Range(0.0, 600.0)),), isolate=False, preset=False,
    inject=Injection("s", "a first-order lag of time constant SIZE s added to the probe",
                     SizeRange(0.0, 86400.0, low_in=False), ("probe_noise",))))
@dataclass
class FirstOrderLag:
    """First-order lag tau dy/dt = x - y, exact for an input held over each sample:

        y_k = y_{k-1} + (1 - exp(-dt/tau)) (x_k - y_{k-1})
    """

    tau_s: float
    dt_s: float = 1.0
    severity: float = 1.0
    _y: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check("tau_s", self.tau_s)
        _check("dt_s", self.dt_s, positive=True)

    def reset(self, x0: float) -> None:
        self._y = x0

    def step(self, x: float, t_s: float) -> float:
        self._y = lag_step(self._y, x, self.tau_s * self.severity, self.dt_s)
        return self._y


@register_block("sensor_noise", fault=Fault(
    "probe_noise", site="ph_sensor", description="pH probe noise (white, seeded)",
    params=(FaultParam("std", "pH", (0.0, 14.0)),), isolate=False, preset=False, candidate=False,
    inject=Injection("pH (std)", "seeded Gaussian noise of standard deviation SIZE pH added",
                     SizeRange(0.0, 14.0, low_in=False), ("probe_noise",))))
@dataclass
class GaussianNoise:
    """Additive white Gaussian noise of standard deviation ``std`` (units of the signal).

    Seeded, so a run is reproducible; the draws depend only on the seed and
    the sample count, never on other blocks.
    """

    std: float
    seed: int = 0
    severity: float = 1.0
    _rng: np.random.Generator = field(init=False, repr=False)
    _block: np.ndarray | None = field(default=None, repr=False)
    _i: int = field(default=0, repr=False)

    def __post_init__(self) -> None:
        _check("std", self.std)
        self._rng = np.random.default_rng(self.seed)

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        if self._block is None or self._i >= len(self._block):
            self._block = self._rng.standard_normal(4096)
            self._i = 0
        e = self._block[self._i]
        self._i += 1
        return x + self.severity * self.std * float(e)


@register_block("sensor_bias", fault=Fault(
    "probe_bias", site="ph_sensor", description="pH probe bias (a diagnosis candidate)",
    params=(FaultParam("bias", "pH", (-14.0, 14.0), search=Range(-3.0, 3.0)),), isolate=False, preset=False,
    inject=Injection("pH", "a step of SIZE pH added to pH", PH_SPAN, ("probe_bias",))))
@dataclass
class Bias:
    """Constant offset: y = x + bias."""

    bias: float
    severity: float = 1.0

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        return x + self.severity * self.bias

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        return np.asarray(x, dtype=float) + self.severity * self.bias


@register_block("sensor_drift", fault=Fault(
    "probe_drift", site="ph_sensor", description="pH probe drift (a diagnosis candidate)",
    # the diagnosis fits up to 3 pH over the record, either sign: a range the record's length sets
    params=(FaultParam("rate_per_s", "pH/s", (-math.inf, math.inf)),), isolate=False, preset=False,
    inject=Injection("pH/min", "a ramp of SIZE pH per minute added to pH", PH_SPAN, ("probe_drift", "probe_bias"))))
@dataclass
class Drift:
    """Linear drift from the moment the block comes to rest: y = x + rate (t - t0)."""

    rate_per_s: float
    severity: float = 1.0
    _t0: float | None = field(default=None, repr=False)

    def reset(self, x0: float) -> None:
        self._t0 = None

    def step(self, x: float, t_s: float) -> float:
        if self._t0 is None:
            self._t0 = t_s
        return x + self.severity * self.rate_per_s * (t_s - self._t0)

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        t_s = np.asarray(t_s, dtype=float)
        if self._t0 is None and len(t_s):
            self._t0 = float(t_s[0])
        return np.asarray(x, dtype=float) + self.severity * self.rate_per_s * (t_s - self._t0)


@register_block("sensor_gain", fault=Fault(
    "probe_gain", site="ph_sensor", description="pH probe slope error about pH 7 (a diagnosis candidate)",
    params=(FaultParam("gain", "1", (0.0, math.inf), search=Range(0.4, 2.5, log=True)),
            FaultParam("reference", "pH", (0.0, 14.0), paper=7.0)), isolate=False, preset=False,
    inject=Injection("fraction", "slope error about pH 7: pH' = 7 + (1 + SIZE)(pH - 7)",
                     SizeRange(-1.0, 10.0, low_in=False), ("probe_bias", "probe_drift"))))
@dataclass
class Gain:
    """Span error about a reference point: y = ref + gain (x - ref) (pH probe slope error about pH 7)."""

    gain: float
    reference: float = 7.0
    severity: float = 1.0

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        g = 1.0 + self.severity * (self.gain - 1.0)
        return self.reference + g * (x - self.reference)

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        g = 1.0 + self.severity * (self.gain - 1.0)
        return self.reference + g * (np.asarray(x, dtype=float) - self.reference)


#: a frozen probe is the block that holds a valve's stem (``blocking``, registered with the valve's blocks), on the
#: probe: the reading stays where the onset found it
register_fault(Fault("probe_frozen", site="ph_sensor", description="pH reading frozen where the onset found it",
                     isolate=False, preset=False, candidate=False,
                     inject=Injection("none", "pH held at its value at the onset (SIZE ignored)", None, ("probe_noise",))),
               "blocking")


@register_block("sensor_asymmetric_lag")
@dataclass
class AsymmetricLag:
    """First-order lag with one time constant for a rising and another for a falling reading.

    A glass electrode can answer a step towards alkaline faster or slower than one towards acid
    (hydration of the gel layer); exact for an input held over each sample.
    """

    tau_up_s: float
    tau_down_s: float
    dt_s: float = 1.0
    severity: float = 1.0
    _y: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check("tau_up_s", self.tau_up_s)
        _check("tau_down_s", self.tau_down_s)
        _check("dt_s", self.dt_s, positive=True)

    def reset(self, x0: float) -> None:
        self._y = x0

    def step(self, x: float, t_s: float) -> float:
        rising = self._y is not None and x > self._y
        self._y = lag_step(self._y, x, self.severity * (self.tau_up_s if rising else self.tau_down_s), self.dt_s)
        return self._y


@register_block("sensor_second_order")
@dataclass
class SecondOrderLag:
    """Two first-order lags in series (tau1_s, tau2_s): a probe whose step response starts with zero slope."""

    tau1_s: float
    tau2_s: float
    dt_s: float = 1.0
    severity: float = 1.0
    _a: FirstOrderLag = field(init=False, repr=False)
    _b: FirstOrderLag = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._a = FirstOrderLag(self.tau1_s, self.dt_s, self.severity)
        self._b = FirstOrderLag(self.tau2_s, self.dt_s, self.severity)

    def reset(self, x0: float) -> None:
        self._a.reset(x0)
        self._b.reset(x0)

    def step(self, x: float, t_s: float) -> float:
        self._a.severity = self._b.severity = self.severity
        return self._b.step(self._a.step(x, t_s), t_s)


@register_block("two_point_calibration")
@dataclass
class TwoPointCalibration:
    """A probe calibrated with two buffers that were off: y = 7 + slope (x - 7) + offset (pH).

    ``slope`` is the electrode's response relative to Nernst (1 = ideal), ``offset`` the reading at pH 7 minus 7.
    """

    slope: float = 1.0
    offset: float = 0.0
    severity: float = 1.0

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        s = 1.0 + self.severity * (self.slope - 1.0)
        return 7.0 + s * (x - 7.0) + self.severity * self.offset

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        s = 1.0 + self.severity * (self.slope - 1.0)
        return 7.0 + s * (np.asarray(x, dtype=float) - 7.0) + self.severity * self.offset
