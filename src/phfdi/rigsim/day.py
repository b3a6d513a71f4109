"""A "day" of the simulated rig: one randomised draw of everything about the rig that a run does not choose.

The teaching-lab rig (``../shared/data/ph_rig``, PROVENANCE.md) is unpublished: its reagent strengths, flask,
probe and pumps are known only through the five recorded runs. Each field of :class:`RigDay` is drawn from a
range (:data:`DAY_RANGES`) taken from what those runs and the project's fits of them show; each range says
where it came from (docs/simulation.md, "A simulated rig for unseen operations", has the table and the
measurements). Two draws with the same day number are the same rig: the same reagent batches, flask, probe
calibration and pumps, as a day of the lab would be.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

#: flow delivered per % of pump command (mL/s per %): the rig's own fixed table, linear per pump. Every
#: (command, flow) pair of the five recorded runs is reproduced at 2 decimals by a slope within
#: [0.06445, 0.06450) for the base pump and [0.07175, 0.07190) for the acid pump (base: 20 % -> 1.29,
#: 50 % -> 3.22, 60 % -> 3.87, 100 % -> 6.45 mL/s; acid: 50 % -> 3.59, 60 % -> 4.31 mL/s); these are
#: the middle of those intervals.
FLOW_PER_PCT = {"acid": 0.071825, "base": 0.064475}
PUMPS = ("acid", "base")


@dataclass(frozen=True)
class Range:
    """A day parameter's range: uniform between ``low`` and ``high`` (log-uniform with ``log``), and its source."""

    low: float
    high: float
    unit: str
    source: str
    log: bool = False

    def draw(self, rng: np.random.Generator) -> float:
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))
        return float(rng.uniform(self.low, self.high))


#: every day parameter's range and where it came from (measurements: docs/simulation.md)
DAY_RANGES: dict[str, Range] = {
    "volume_ml": Range(3000.0, 5000.0, "mL", "phfdi calibrate --estimator on every four of the five runs: "
                       "3871-4924 mL; phfdi diagnose's calibrations per fold: 1.7-5.1 L (docs/diagnosis.md)"),
    # the records fix only a reagent's strength per flask volume (the pH moves with charge per volume): drawn as
    # such, the strengths in mM are these times the volume in litres
    "acid_per_litre": Range(0.9, 3.0, "mM of charge per L of flask", "what the recorded acid phases imply "
                            "(charge to pass from plateau to plateau / acid delivered): February acid addition 2.7, "
                            "February closed loop 1.6-1.9, April 1.0-1.7; the estimator's fits on four runs 1.2-2.7, "
                            "diagnose's calibrations 1.05-1.7 (log-uniform)", log=True),
    "base_per_litre": Range(4.5, 12.0, "mM of charge per L of flask", "the same for the base phases: February base "
                            "addition 5.2, February closed loop 6.8-7.2, March 10.9; the estimator's fits 5.2-7.9, "
                            "diagnose's 4.5-7.3 (log-uniform)", log=True),
    "carbonate_per_naoh": Range(0.005, 0.03, "mol/mol", "CO2 taken up by the open caustic vat; diagnose fits "
                                "carbonate in the caustic at 0.55 mM in 12-20 mM NaOH (April), named it for the "
                                "February base run; the knees bound all buffering (below)"),
    "flask_carbonate_mM": Range(0.0, 0.15, "mM", "carbonate the flask holds at a run's start beyond its mix of "
                                "feeds (CO2 taken up while it stood): diagnose fits 0.12 mM in the April flask"),
    "buffer_pka": Range(7.0, 8.5, "pH", "diagnose fitted on the April titration: a weak acid of pKa 7.88-7.98"),
    "buffer_mM": Range(0.01, 0.15, "mM", "the same fit: 0.15-0.17 mM; the recorded knees pass pH 9..5 with 0.13-0.2 "
                       "mM of buffering in all (titrant rate x passage time), and the February acid addition falls "
                       "from pH 7 to 4 in 8 s, which only a flask with next to none allows (log-uniform)", log=True),
    "co2_kla_per_s": Range(1e-4, 1e-3, "1/s", "surface uptake of a stirred flask (docs/diagnosis.md, physics check "
                           "on co2_absorption)", log=True),
    "co2_equilibrium_mM": Range(0.01, 0.02, "mM", "air at 400 ppm CO2 with Henry 0.034 M/atm: 0.014 mM"),
    "zone_tau_s": Range(3.0, 12.0, "s", "a mixing zone at the probe fitted in filter form: tau 5.4-11.4 s "
                        "(benchmarks/rig_mixing_state.py)"),
    "zone_volume_fraction": Range(0.005, 0.02, "of the flask", "a small zone around the probe; with no feed "
                                  "dosed into it only its time constant shows in the pH"),
    "probe_tau_s": Range(1.0, 3.0, "s", "a glass electrode's response; the recorded knees pass pH 5-9 in "
                         "4.5-19 s where the flask alone needs a few"),
    "white_noise_ph": Range(0.006, 0.012, "pH", "the reading's noise outside the stroke band: the recorded "
                            "readings' noise is mostly the band (next rows); this part barely moves their statistics"),
    "acid_ripple_ph": Range(0.038, 0.058, "pH (std)", "robust noise of the detrended reading while the acid pump "
                            "runs: 0.043-0.057 pH on the three runs with acid"),
    "base_ripple_ph": Range(0.02, 0.028, "pH (std)", "the same with the base pump alone: 0.024-0.026 pH on two runs"),
    "acid_stroke_s": Range(1.2, 1.5, "s", "period of the detrended readings' spectral peak: 1.23-1.48 s"),
    "base_stroke_s": Range(1.2, 1.5, "s", "the same"),
    "stroke_coherence_s": Range(0.45, 0.65, "s", "how long the stroke ripple keeps its phase: the recorded "
                                "readings' autocorrelation is -0.08 to -0.15 one sample apart, -0.34 to -0.39 two"),
    "probe_offset_ph": Range(-0.05, 0.05, "pH", "a healthy two-point calibration"),
    "probe_slope": Range(0.98, 1.01, "1", "a healthy electrode's slope relative to Nernst"),
    "probe_drift_ph_per_h": Range(-0.02, 0.02, "pH/h", "no significant drift in the real runs (diagnose: "
                                  "sensor drift not significant); kept below the noise over an hour"),
    "room_temp_c": Range(21.5, 23.2, "deg C", "T_Room of the real runs: 21.6-23.1 deg C"),
    "idle_ripple_ph": Range(0.0, 0.025, "pH (std)", "the band's noise while neither pump runs: no recorded run stops "
                            "both, so from none (the hump is the pumps') to the base pump's level (the meter's own)"),
}


@dataclass(frozen=True)
class RigDay:
    """One draw of the rig: reagents, flask, mixing, probe, pumps and room (units in the names).

    Strengths are in mM of charge as ``phfdi calibrate --estimator`` reports them: the acid's is negative
    (H2SO4 at half its magnitude in mM), the base's positive (NaOH); drawn as strength per litre of flask
    (``acid_per_litre``, ``base_per_litre`` of :data:`DAY_RANGES`) times the volume.

    Examples
    --------
    >>> from phfdi.rigsim import draw_day
    >>> day = draw_day(3)
    >>> day == draw_day(3), day == draw_day(4)
    (True, False)
    >>> 3000.0 <= day.volume_ml <= 5000.0 and 0.9 <= -day.acid_strength_mM / (day.volume_ml / 1000.0) <= 3.0
    True
    """

    number: int
    volume_ml: float
    acid_strength_mM: float
    base_strength_mM: float
    carbonate_per_naoh: float
    flask_carbonate_mM: float
    buffer_pka: float
    buffer_mM: float
    co2_kla_per_s: float
    co2_equilibrium_mM: float
    zone_tau_s: float
    zone_volume_fraction: float
    probe_tau_s: float
    white_noise_ph: float
    acid_ripple_ph: float
    base_ripple_ph: float
    idle_ripple_ph: float
    acid_stroke_s: float
    base_stroke_s: float
    stroke_coherence_s: float
    probe_offset_ph: float
    probe_slope: float
    probe_drift_ph_per_h: float
    room_temp_c: float

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "RigDay":
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        missing = sorted(names - set(d))
        if unknown or missing:
            raise ValueError(f"rig day: unknown {unknown} / missing {missing}")
        values = {k: float(v) for k, v in d.items() if k != "number"}
        return cls(number=int(d["number"]), **values)  # type: ignore[arg-type]

    def with_values(self, **changes: float) -> "RigDay":
        """A copy with some fields replaced (a test pins a parameter, a study varies one)."""
        d = self.to_dict()
        unknown = sorted(set(changes) - set(d))
        if unknown:
            raise ValueError(f"rig day has no parameter {unknown[0]!r}")
        d.update(changes)
        return RigDay.from_dict(d)


#: separates the day's random stream from a run's (a run with seed N on day N draws other numbers)
_DAY_STREAM = 0x5EED_DA7


def draw_day(number: int) -> RigDay:
    """The rig on day ``number`` (any non-negative integer): every :data:`DAY_RANGES` parameter drawn.

    Examples
    --------
    >>> from phfdi.rigsim import draw_day
    >>> round(draw_day(0).zone_tau_s, 2) == round(draw_day(0).zone_tau_s, 2)
    True
    """
    if number < 0:
        raise ValueError(f"day must be a non-negative integer, got {number}")
    rng = np.random.default_rng([_DAY_STREAM, int(number)])
    drawn = {name: r.draw(rng) for name, r in DAY_RANGES.items()}
    litres = drawn["volume_ml"] / 1000.0
    drawn["acid_strength_mM"] = -drawn.pop("acid_per_litre") * litres
    drawn["base_strength_mM"] = drawn.pop("base_per_litre") * litres
    return RigDay(number=int(number), **drawn)
