"""Estimator reference: a Kalman filter on the flask's reaction invariant, driven by the measured pH.

For a stirred overflow vessel fed by pumps of strong acid and strong base (the teaching-lab rig of
../shared/data/ph_rig: H2SO4 and NaOH into a flask), where an open-loop simulation drifts away from a
real run within minutes (docs/diagnosis.md: held-out NRMSE near 1). Instead of simulating, the filter
follows the plant: every sample it predicts the next pH from the physics and the measured pump flows,
compares it with the measured pH and corrects its state by the Kalman gain. The innovations
(measured - predicted pH, in units of their predicted standard deviation) are the residual the
wavelet-CUSUM bank watches (:mod:`wavelet_fdi.learned_detector`). A healthy plant gives innovations of
unit variance whatever its reagent strengths or starting contents; a fault the physics cannot produce
(a probe that jumps, freezes or drifts; a pump that delivers other than recorded) gives innovations
the filter's noise model does not expect.

The model (reaction invariants, Gustafsson & Waller 1983; the charge-balance form of Wright & Kravaris
1991). The state is the excess of strong base over strong acid in the vessel, x = [Na+] - 2[SO4 2-]
(mM, "charge equivalents"), which reactions do not change:

    dx/dt = sum_i f_i s_i q_i / V - (sum_i q_i / V) x          (overflow: constant volume V)

with feed i's flow q_i (mL/s, the record's column), signed strength s_i (mM of charge: + base, - acid)
and an adapted strength factor f_i (below). The measured pH follows from the charge balance

    x = Kw/h - h + sum_j c_j Ka_j / (Ka_j + h)                  (h = [H+], mM)

with a weak background buffer c_j (a ladder of pKa 3..11 and carbonate, what tap water and air bring;
concentrations fitted) that keeps the titration curve's slope finite. The curve is tabulated once on
a 0.001 pH grid; x(pH) is explicit and pH(x) an interpolation in that table.

The filter (a scalar Kalman filter in x; the measurement is mapped into x exactly through the curve,
so its update needs no linearisation):

    x-  = x_ss + (x - x_ss) exp(-D dt),   P- = a^2 P + (rate_rel_std * (x- - x))^2 + (walk * beta(pH-))^2 dt
    x_m = x(pH_measured),                 R  = (probe_noise * beta(pH_measured))^2 + curve_std^2
    K = P- / (P- + R),   x = x- + K (x_m - x-),   P = (1 - K) P-

beta = dx/dpH is the buffer capacity. The residual (``innovation: x``) is the standardised innovation
nu / sqrt(S), nu = x_m - x-, S = P- + R (+ the timing term below): exactly the quantity whose Gaussian
likelihood the fit maximises, so its healthy scale is what the fit promised. The first format
(``innovation: ph``, files written before 2026-11-28) divided the pH innovation pH_measured - pH(x-) by
a linearised standard deviation sqrt((P- + curve_std^2) / beta(pH-)^2 + probe_noise^2), with beta taken
at the predicted pH: at the knee of a titration, where beta changes tenfold within half a pH, that
standard deviation is too small on the steep side, and a reading landing there read as 6 to 8 sigma.
The residual is limited to +-``clip_sigma`` (4): a one-sample outlier then moves the CUSUMs no more than
a 4-sigma sample, while a fault that persists still adds 4 sigma a sample (the psi-function of robust
filtering: Masreliez & Martin 1977). The Kalman update itself is gated (``gate_sigma``, set at calibration to
the detector's spike level, which a healthy innovation passes once in a million samples): a reading beyond it is
held, the state predicted across it, until the next reading says what it was. Beyond the gate on the same side
too, the pH did move that far (a step, a knee the model's timing missed): the held reading's update is made after
all, then the next one's, and the filter is where it would have been. Otherwise the held reading was a lone
outlier and is dropped: the state stays where it was. Ungated, where the curve is steeper than at the true pH a
glitch's measurement reads as more precise, the state jumped to a 1 pH glitch and crawled back over ten samples,
and the return read as a probe offset: a third of such glitches on the rig were fault alarms.

Adaptation ("slowly adapted run parameters"). Day-to-day the reagents' strengths differ by tens of per
cent (docs/diagnosis.md), which a fixed model would call a fault on every run. Each feed's factor f_i
is re-estimated at every block boundary (``block_samples``) by least squares of the filter's
corrections K*nu on the feeds' modelled contributions over the block, and moved toward it with gain
(seconds that feed ran in the block) / ``adapt_time_constant_s``: a strength error is absorbed with
that time constant of pump-on time. A fault that appears faster (a pump that suddenly delivers 30 %
less, any probe fault) shows in the innovations first. The flask's starting contents need no
adaptation: the state starts at x(first pH) and the filter keeps it. A probe offset is not adapted:
with one pH probe it cannot be told from the contents x (both move the reading), so the contents
absorb a constant offset at the start, and an offset that appears later is a fault.

Zones (``adapt_zones_ph``, default pH 5 and 9). The factors are kept per pH zone: the step's prediction
uses, and its correction adapts, the factors of the zone the filter's pH is in. Why: what the filter
adapts is a feed's *apparent* strength, the modelled change of x against the change the curve reads,
and on the rig that depends on the pH: in the closed-loop run the acid's factor settles at 0.55 on the
basic plateaus and climbs to 1.2-1.35 on the acid side, within one run of one reagent (a buffer the
curve lacks, carbonate most likely, whose pKa 10.33 sits in the basic zone). One factor for every pH
carried the basic side's value to the acid side (April's titration: 0.27 at the landing, innovations
at -1.5 sigma for 40 s and a false alarm). The boundaries are the chemistry's, not fitted: below pH 5
the curve's buffer capacity is carried by H+, above 9 by OH-, between them any weak buffer dominates.

The noise model (probe_noise, rate_rel_std, walk, curve_std), the strengths, the volume and the buffer
are fitted on healthy runs by maximising the innovations' Gaussian likelihood (the prediction-error
method for state-space models: Ljung 1999, ch. 7; Schweppe 1965), :func:`wavelet_fdi.estimator_fit.fit_reference`.

Any chunking of a record gives bit-identical residuals: the recursion runs sample by sample and the
adaptation acts at fixed global sample indices. It runs compiled (:mod:`wavelet_fdi.estimator_kernel`,
Numba: about 0.3 us a sample against 3.2-3.5 us as plain Python), operation for operation as written there.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from phfdi_base.errors import UserError

from .estimator_kernel import compiled

KIND = "estimator"
LN10 = math.log(10.0)
KW_MM2 = 1e-8  # water's ion product at 25 degC, (mM)^2
PH_GRID = np.linspace(0.0, 14.0, 14001)  # 0.001 pH steps
LADDER_PKAS = tuple(float(p) for p in range(3, 12))  # the background buffer: one weak acid per pH unit
CARBONATE_PKAS = (6.35, 10.33)
#: the adaptation's pH zones (the estimator's default): where a strong acid-base curve's buffer capacity is
#: carried by H+ (below pH 5), by OH- (above 9), and the steep part between, where any weak buffer the
#: curve lacks dominates it. Chosen from the chemistry, before any run was scored with them (module doc).
ADAPT_ZONES_PH = (5.0, 9.0)
#: the residual's robust limit (healthy sigmas): a standardised innovation beyond it counts as this much
CLIP_SIGMA = 4.0
#: what the residual is: "x", the filter's standardised innovation nu / sqrt(S) (the term of its likelihood), or
#: "ph", the pH innovation over its linearised standard deviation (files written before 2026-11-28)
INNOVATIONS = ("x", "ph")
FACTOR_BOUNDS = (0.25, 4.0)  # an adapted strength factor stays within these
MAX_BLOCK_STEP = 0.5  # relative error one block may report


@dataclass(frozen=True)
class Feed:
    """One pumped feed: the record's flow channel (mL/s) and its strength in mM of charge (+ base, - acid)."""

    channel: str
    strength_mM: float

    def __post_init__(self) -> None:
        if not math.isfinite(self.strength_mM) or self.strength_mM == 0.0:
            raise UserError(f"feed {self.channel!r}: strength must be a non-zero number of mM (+ base, - acid)")


@dataclass(frozen=True)
class NoiseModel:
    """What the filter expects of a healthy plant (fitted with the chemistry)."""

    probe_noise_ph: float = 0.03  # measurement noise of the pH probe (pH)
    rate_rel_std: float = 0.3  # relative uncertainty of one step's modelled change of x
    walk_ph_per_sqrt_s: float = 0.005  # unexplained random walk of the pH (pH per sqrt(s))
    curve_std_mM: float = 1e-6  # uncertainty of the titration curve (mM of x); not fitted (fits drove it to 0)
    timing_s: float = 0.5  # timing uncertainty of what the probe sees (mixing, probe response): s

    def check(self) -> "NoiseModel":
        for k, v in asdict(self).items():
            if not (math.isfinite(v) and v > 0):
                raise UserError(f"estimator noise model: {k} must be a positive number, got {v}")
        return self


@dataclass(frozen=True)
class EstimatorReference:
    """A Kalman filter of a stirred overflow vessel's reaction invariant (see the module docstring).

    Examples
    --------
    >>> ref = EstimatorReference((Feed("acid_flow_ml_s", -3.4), Feed("base_flow_ml_s", 20.0)),
    ...                          "ph_measured", volume_ml=4000.0)
    >>> ref.channels, ref.residual_channels
    (('acid_flow_ml_s', 'base_flow_ml_s', 'ph_measured'), ('ph_measured',))
    >>> round(ref.ph_of_x(0.0), 2), round(ref.ph_of_x(1.0), 2)  # neutral; 1 mM of excess base
    (7.0, 11.0)
    """

    feeds: tuple[Feed, ...]
    ph_channel: str
    volume_ml: float
    buffer_mM: float = 0.0  # each weak acid of the ladder (pKa 3..11)
    carbonate_mM: float = 0.0
    noise: NoiseModel = field(default_factory=NoiseModel)
    adapt_time_constant_s: float = 120.0  # 0: no adaptation
    block_samples: int = 32
    #: pH boundaries of the adaptation's zones: each zone adapts its own strength factors (see the module doc)
    adapt_zones_ph: tuple[float, ...] = ADAPT_ZONES_PH
    innovation: str = "x"
    #: 0: no limit
    clip_sigma: float = CLIP_SIGMA
    #: False: the same physics run open loop from the first pH (never corrected): a simulation reference
    correct: bool = True
    fit_info: dict = field(default_factory=dict, compare=False)
    #: the margins by which a fault hypothesis must beat healthy operation re-adapted before an alarm is a fault
    #: (wavelet_fdi.estimator_isolation, "Confirmation"); empty: every alarm is named a fault (files from before)
    confirm: dict = field(default_factory=dict, compare=False)
    #: a reading whose standardised innovation exceeds this is held until the next one says whether it was a lone
    #: outlier (dropped) or the pH moving (updated after all) (0: never): the detector's spike level, set at
    #: calibration
    gate_sigma: float = 0.0

    kind = KIND
    lags = 1  # the first sample only starts the state

    def __post_init__(self) -> None:
        if not self.feeds:
            raise UserError("the estimator needs at least one feed")
        if not (math.isfinite(self.volume_ml) and self.volume_ml > 0):
            raise UserError(f"estimator: volume_ml must be positive, got {self.volume_ml}")
        if self.buffer_mM < 0 or self.carbonate_mM < 0:
            raise UserError("estimator: buffer and carbonate concentrations must be >= 0")
        if self.adapt_time_constant_s < 0 or self.block_samples < 1:
            raise UserError("estimator: adapt_time_constant_s must be >= 0 and block_samples >= 1")
        zones = tuple(float(b) for b in self.adapt_zones_ph)
        if any(not (0.0 < b < 14.0) for b in zones) or list(zones) != sorted(set(zones)):
            raise UserError(f"estimator: adapt_zones_ph must be increasing pH values within 0..14, got {list(zones)}")
        object.__setattr__(self, "adapt_zones_ph", zones)
        if self.innovation not in INNOVATIONS:
            raise UserError(f"estimator: innovation must be one of {', '.join(INNOVATIONS)}, got {self.innovation!r}")
        if not (self.clip_sigma == 0.0 or self.clip_sigma > 0.0):  # also refuses NaN
            raise UserError(f"estimator: clip_sigma must be 0 (no limit) or positive, got {self.clip_sigma}")
        if not (self.gate_sigma == 0.0 or self.gate_sigma > 0.0):
            raise UserError(f"estimator: gate_sigma must be 0 (no gate) or positive, got {self.gate_sigma}")
        self.noise.check()
        # a hypothesis or a fit evaluation changes a noise term or a strength, not the curve: share its table
        x, beta, x_list = _curve_tables(float(self.buffer_mM), float(self.carbonate_mM))
        object.__setattr__(self, "_x_table", x)
        object.__setattr__(self, "_beta_table", beta)
        object.__setattr__(self, "_x_list", x_list)

    # ---- the protocol every reference kind shares ------------------------------------------
    @property
    def channels(self) -> tuple[str, ...]:
        """The record's channels this reference reads, in the order of the rows it is given."""
        return tuple(f.channel for f in self.feeds) + (self.ph_channel,)

    @property
    def residual_channels(self) -> tuple[str, ...]:
        return (self.ph_channel,)

    @property
    def feed_directions(self) -> tuple[int, ...]:
        """Per feed, the way it moves the pH: -1 an acid, +1 a base (its strength's sign; wavelet_fdi.feed_checks)."""
        return tuple(1 if f.strength_mM > 0 else -1 for f in self.feeds)

    def new_state(self) -> "EstimatorStream":
        return EstimatorStream(self)

    def residuals(self, t_s: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Innovations of a whole record (n, len(channels)) in predicted-sigma units (a fresh stream)."""
        return self.new_state().residuals(t_s, x)

    def to_dict(self) -> dict:
        return {"kind": KIND, "feeds": [asdict(f) for f in self.feeds], "ph_channel": self.ph_channel,
                "volume_ml": self.volume_ml, "buffer_mM": self.buffer_mM, "carbonate_mM": self.carbonate_mM,
                "noise": asdict(self.noise), "adapt_time_constant_s": self.adapt_time_constant_s,
                "block_samples": self.block_samples, "adapt_zones_ph": list(self.adapt_zones_ph),
                "innovation": self.innovation, "clip_sigma": self.clip_sigma, "correct": self.correct,
                "fit": self.fit_info, **({"confirm": self.confirm} if self.confirm else {}),
                **({"gate_sigma": self.gate_sigma} if self.gate_sigma else {})}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "EstimatorReference":
        try:
            feeds = tuple(Feed(str(f["channel"]), float(f["strength_mM"])) for f in d["feeds"])
            cls._check_signs(d, where)
            return cls(feeds, str(d["ph_channel"]), float(d["volume_ml"]), float(d.get("buffer_mM", 0.0)),
                       float(d.get("carbonate_mM", 0.0)), NoiseModel(**{k: float(v) for k, v in d["noise"].items()}),
                       float(d.get("adapt_time_constant_s", 120.0)), int(d.get("block_samples", 32)),
                       # a file written before the zones adapted one factor per feed at every pH
                       tuple(float(b) for b in d.get("adapt_zones_ph", ())),
                       str(d.get("innovation", "ph")), float(d.get("clip_sigma", 0.0)),
                       bool(d.get("correct", True)), dict(d.get("fit") or {}),
                       checked_confirm(d.get("confirm") or {}, f"{where}: confirm"),
                       float(d.get("gate_sigma", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: not an estimator reference ({exc})") from None

    @staticmethod
    def _check_signs(d: dict, where: str) -> None:
        """A strength whose sign differs from the one its fit started from (acid -, base +: the plant model's) is a
        hand edit that turns an acid into a base: refused naming the feed."""
        signs = (d.get("fit") or {}).get("strength_signs")
        if not isinstance(signs, list):
            return
        for f, sign in zip(d["feeds"], signs):
            if float(f["strength_mM"]) * float(sign) < 0:
                raise UserError(f"{where}: feed {f['channel']!r}: strength {f['strength_mM']} mM has the wrong sign "
                                f"(fitted as {'base, +' if sign > 0 else 'acid, -'}); an acid's is negative, a base's "
                                f"positive")

    # ---- the titration curve ---------------------------------------------------------------
    def x_of_ph(self, ph: np.ndarray) -> np.ndarray:
        """Excess base (mM) at these pH values (the curve, interpolated)."""
        return np.interp(ph, PH_GRID, self._x_table)  # type: ignore[attr-defined]

    def beta_of_ph(self, ph: np.ndarray) -> np.ndarray:
        """Buffer capacity dx/dpH (mM per pH)."""
        return np.interp(ph, PH_GRID, self._beta_table)  # type: ignore[attr-defined]

    def ph_of_x(self, x: float) -> float:
        xs: list[float] = self._x_list  # type: ignore[attr-defined]
        i = min(max(bisect.bisect_left(xs, x), 1), len(xs) - 1)
        lo, hi = xs[i - 1], xs[i]
        frac = 0.0 if hi == lo else min(max((x - lo) / (hi - lo), 0.0), 1.0)
        return float(PH_GRID[i - 1] + frac * (PH_GRID[i] - PH_GRID[i - 1]))

    def with_values(self, **changes) -> "EstimatorReference":
        return replace(self, **changes)


def checked_confirm(d: dict, where: str) -> dict:
    """A reference file's confirmation margins, checked: each a positive number (a damaged entry is one line)."""
    if not d:
        return {}
    if not isinstance(d, dict) or not isinstance(d.get("thresholds"), dict):
        raise UserError(f"{where}: expected a mapping with 'thresholds'")
    for k, v in d["thresholds"].items():
        if not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise UserError(f"{where}: threshold {k!r} must be a positive number, got {v!r}")
    band = d.get("noise_band")
    if band is not None and (not isinstance(band, list) or len(band) != 2
                             or not all(isinstance(b, (int, float)) and b > 0 for b in band) or band[0] > band[1]):
        raise UserError(f"{where}: noise_band must be [low, high] positive scales, got {band!r}")
    return dict(d)


@functools.lru_cache(maxsize=64)
def _curve_tables(buffer_mM: float, carbonate_mM: float) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """The curve's tables, computed once per buffer: every reference with this buffer shares them (nothing
    writes them; they stay writeable arrays so that the compiled filter keeps one signature)."""
    x, beta = titration_curve(buffer_mM, carbonate_mM)
    return x, beta, x.tolist()


def titration_curve(buffer_mM: float, carbonate_mM: float) -> tuple[np.ndarray, np.ndarray]:
    """x(pH) (mM of excess strong base) and beta(pH) = dx/dpH on :data:`PH_GRID`."""
    h = 1000.0 * 10.0 ** -PH_GRID
    x = KW_MM2 / h - h
    beta = KW_MM2 / h + h
    for pka, c in [(p, buffer_mM) for p in LADDER_PKAS] + [(p, carbonate_mM) for p in CARBONATE_PKAS]:
        if c <= 0:
            continue
        ka = 1000.0 * 10.0 ** -pka
        x = x + c * ka / (ka + h)
        beta = beta + c * ka * h / (ka + h) ** 2
    return x, LN10 * beta


class EstimatorStream:
    """The filter's state between chunks: x, P, the strength factors and the block's adaptation sums (arrays the
    compiled recursion, :mod:`wavelet_fdi.estimator_kernel`, updates in place)."""

    def __init__(self, ref: EstimatorReference) -> None:
        self.ref = ref
        m = len(ref.feeds)
        zones = len(ref.adapt_zones_ph) + 1
        self.x: float | None = None
        self.p: float = 0.0
        #: each pH zone's strength factors (one zone when ``adapt_zones_ph`` is empty)
        self._zf = np.ones((zones, m))
        self.zone = 0  # the zone of the state's pH
        self._qp = np.zeros(m)  # the last flows (a missing flow holds the last one)
        self.last_t: float | None = None
        self.samples = 0
        # block sums for the strength adaptation, per zone
        self._gg = np.zeros((zones, m, m))
        self._gy = np.zeros((zones, m))
        self._on_s = np.zeros((zones, m))
        self.nll = 0.0  # running negative log-likelihood of the innovations (for fitting)
        self.blocks = 0  # block boundaries passed (the adaptation's clock: block_samples samples each)
        #: the reading held at the gate, waiting for the next to say what it was: (innovation, its variance, side;
        #: side 0: none held)
        self.held: tuple[float, float, float] = (0.0, 1.0, 0.0)
        #: the standardised innovations of the last :meth:`residuals` call before the limit ``clip_sigma`` (n, 1):
        #: what a test of single large innovations reads (the residual itself counts an outlier as clip_sigma)
        self.last_unlimited: np.ndarray = np.empty((0, 1))
        #: set to a list to record every adaptation: (block boundary, relative errors, pump-on s, factors before,
        #: zone)
        self.adapt_trace: list[tuple[int, list[float], list[float], list[float], int]] | None = None

    @property
    def zone_factors(self) -> list[list[float]]:
        """Each pH zone's strength factors (a copy)."""
        return self._zf.tolist()

    @property
    def factors(self) -> list[float]:
        """The strength factors in force at the state's pH (its zone's; a copy)."""
        return self._zf[self.zone].tolist()

    @property
    def last_flows(self) -> list[float]:
        return self._qp.tolist()

    def fork(self, ref: EstimatorReference | None = None) -> "EstimatorStream":
        """A copy of this state (the same or another reference, e.g. a fault hypothesis), log-likelihood reset."""
        other = EstimatorStream(ref or self.ref)
        other.x, other.p, other.last_t, other.samples = self.x, self.p, self.last_t, self.samples
        other.blocks, other.zone, other.held = self.blocks, self.zone, self.held
        other._zf, other._qp = self._zf.copy(), self._qp.copy()
        other._gg, other._gy, other._on_s = self._gg.copy(), self._gy.copy(), self._on_s.copy()
        return other

    def residuals(self, t_s: np.ndarray, rows: np.ndarray, noise_at_ph: np.ndarray | None = None) -> np.ndarray:
        """Innovations of the next rows (n, len(channels)) at times t_s, in predicted-sigma units.

        ``noise_at_ph``: the pH at which the reading's noise is mapped into x (default: the reading). A hypothesis
        that moves the reading (a probe offset) keeps the noise where it was read: the probe's noise does not
        change with its offset, and a shift of the curve's buffer capacity would otherwise pass for evidence.
        """
        ref = self.ref
        rows = np.asarray(rows, dtype=float)
        t = np.ascontiguousarray(t_s, dtype=float)
        m = len(ref.feeds)
        if rows.ndim != 2 or rows.shape[1] != m + 1:
            raise ValueError(f"expected rows x {m + 1} channels ({', '.join(ref.channels)}), got shape {rows.shape}")
        ph = np.ascontiguousarray(rows[:, m])
        ok = np.isfinite(ph)
        php = np.where(ok, ph, 7.0)
        xm = ref.x_of_ph(php)
        nz = ref.noise
        at = php if noise_at_ph is None else np.where(np.isfinite(noise_at_ph), noise_at_ph, 7.0)
        r_meas = (nz.probe_noise_ph * ref.beta_of_ph(at)) ** 2 + nz.curve_std_mM ** 2
        n = len(t)
        out = np.full(n, math.nan)
        unlimited = np.full(n, math.nan)
        if n:
            self._run(t, np.array(rows[:, :m]), ok, xm, r_meas, ph, out, unlimited)
        self.last_unlimited = unlimited[:, None]
        return out[:, None]

    def _run(self, t, flows, ok, xm, r_meas, ph, out, unlimited) -> None:
        """The compiled recursion over one chunk (:func:`wavelet_fdi.estimator_kernel.compiled`); the state comes
        in and goes back out through its arguments."""
        ref, nz = self.ref, self.ref.noise
        lo, hi = FACTOR_BOUNDS
        consts = (float(ref.volume_ml), nz.rate_rel_std ** 2, nz.walk_ph_per_sqrt_s ** 2, nz.curve_std_mM ** 2,
                  nz.probe_noise_ph ** 2, float(nz.timing_s), float(ref.clip_sigma or math.inf),
                  float(ref.gate_sigma or math.inf),
                  float(ref.adapt_time_constant_s), lo, hi, MAX_BLOCK_STEP)
        flags = (int(ref.block_samples), bool(ref.correct), ref.adapt_time_constant_s > 0, ref.innovation == "x")
        started = self.x is not None
        scalars = (started, float(self.x) if self.x is not None else 0.0, float(self.p),
                   float(self.last_t) if self.last_t is not None else 0.0, int(self.zone), int(self.samples),
                   float(self.nll), int(self.blocks), *self.held)
        m, zones = len(ref.feeds), self._zf.shape[0]
        most = (len(t) // ref.block_samples + 2) * zones  # adaptations this chunk can record
        trace = (np.zeros(most, dtype=np.int64), np.zeros((most, m)), np.zeros((most, m)), np.zeros((most, m)),
                 np.zeros(most, dtype=np.int64))
        strengths = np.array([f.strength_mM for f in ref.feeds])
        state, ntrace = compiled()(t, flows, ok, xm, r_meas, ph, out, unlimited, strengths, ref._x_table,  # type: ignore[attr-defined]
                                   ref._beta_table, np.array(ref.adapt_zones_ph, dtype=float),  # type: ignore[attr-defined]
                                   self._zf, self._gg, self._gy, self._on_s, self._qp, np.zeros(m), *trace,
                                   consts, flags, scalars)
        started, x, self.p, last_t, self.zone, self.samples, self.nll, self.blocks, *held = state
        self.held = (float(held[0]), float(held[1]), float(held[2]))
        self.x, self.last_t = (float(x), float(last_t)) if started else (None, None)
        if self.adapt_trace is not None:
            blocks, rel, on, fac, zone = trace
            self.adapt_trace += [(int(blocks[i]), rel[i].tolist(), on[i].tolist(), fac[i].tolist(), int(zone[i]))
                                 for i in range(ntrace)]


def compile_filter() -> None:
    """Compile the filter for the argument types the stream passes (and write Numba's cache): what
    ``scripts/setup.sh`` does once, so that the first replay or detector node does not wait about 10 s for it."""
    ref = EstimatorReference((Feed("acid_flow_ml_s", -10.0), Feed("base_flow_ml_s", 20.0)), "ph_measured", 1000.0)
    ref.residuals(np.arange(40) * 0.35, np.column_stack((np.ones(40), np.full(40, 2.0), np.linspace(3.0, 11.0, 40))))
