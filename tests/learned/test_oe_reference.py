"""The output-error learned reference (kind ``oe``): chunking, the file, and a sensor step that stays."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedSettings, learn, run_record
from wavelet_fdi.reference_oe import OutputErrorReference
from wavelet_fdi.references import KINDS, reference_from_dict

CHANNELS = ("flow", "level")


def plant(n: int, seed: int) -> np.ndarray:
    """A wandering flow and a level that follows it (first order), each measured with sensor noise."""
    rng = np.random.default_rng(seed)
    e, w = rng.normal(size=n), rng.normal(size=n)
    u, y = np.zeros(n), np.zeros(n)
    for t in range(1, n):
        u[t] = 0.98 * u[t - 1] + e[t]
        y[t] = 0.95 * y[t - 1] + 0.05 * u[t] + 0.02 * w[t]
    return np.column_stack([10.0 + u + 0.3 * rng.normal(size=n), 5.0 + y + 0.1 * rng.normal(size=n)])


def test_registered_and_file_round_trip():
    x = plant(1500, 1)
    ref = OutputErrorReference.fit(x, CHANNELS)
    assert KINDS["oe"] is OutputErrorReference
    back = reference_from_dict(ref.to_dict())
    assert isinstance(back, OutputErrorReference)
    assert np.array_equal(back.residuals(None, x), ref.residuals(None, x), equal_nan=True)
    with pytest.raises(UserError):
        reference_from_dict({**ref.to_dict(), "correction_samples": 0.5})


@pytest.mark.parametrize("seed", [1, 2])
def test_any_chunking_gives_bit_identical_residuals(seed):
    rng = np.random.default_rng(seed)
    x = plant(3000, seed)
    x[rng.integers(0, 3000, 40), rng.integers(0, 2, 40)] = np.nan  # missing samples on both channels
    ref = OutputErrorReference.fit(x[:1500], CHANNELS)
    whole = ref.residuals(None, x)
    st, parts, i = ref.new_state(), [], 0
    while i < len(x):
        k = int(rng.integers(1, 400))
        parts.append(st.residuals(None, x[i:i + k]))
        i += k
    assert np.array_equal(whole, np.vstack(parts), equal_nan=True)
    assert np.isnan(whole[np.isnan(x)]).all()
    assert np.all(np.abs(np.nanstd(whole[2:1500], axis=0) - 1.0) < 0.05)  # healthy-sigma units on the fit rows
    assert np.all(np.nanstd(whole[1500:], axis=0) < 1.5)  # and close on new healthy rows


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_sensor_step_that_stays_keeps_the_oe_alarm_while_arx_forgets_it(seed):
    """The level sensor jumps by a few of its noise widths and stays (onset and size drawn, never given to the
    code): the ARX reference's level residual has it for one sample; the OE one keeps alarming."""
    rng = np.random.default_rng(50 + seed)
    n = 4000
    x = plant(n, seed)
    onset = int(rng.integers(2000, 3000))
    faulty = x.copy()
    faulty[onset:, 1] += float(rng.uniform(0.5, 0.8))
    t = np.arange(n, dtype=float)
    states = {}
    for form in ("arx", "oe"):
        model = learn(x[:1500], CHANNELS, LearnedSettings(form=form))
        _, healthy, _ = run_record(model, t, x)
        assert healthy.sum() == 0, f"{form}: alarm on the healthy record"
        _, states[form], _ = run_record(model, t, faulty)
        assert states[form][:onset].sum() == 0, f"{form}: alarm before the fault"
    assert states["oe"][onset:onset + 30].any(), "oe: no alarm within 30 samples of the onset"
    assert states["oe"][onset + 50:onset + 100].mean() > 0.9, "oe: the alarm does not hold"
    assert states["arx"][onset + 50:onset + 100].sum() == 0  # the reason for the kind


def test_bad_settings_are_user_errors():
    with pytest.raises(UserError):
        LearnedSettings(form="armax").check()
    with pytest.raises(UserError):
        OutputErrorReference.fit(plant(500, 1), CHANNELS, correction_samples=0.5)
