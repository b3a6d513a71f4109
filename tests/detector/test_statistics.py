"""The vectorised CUSUM bank is Page's recursion, and chunking does not change a bit of it."""

from __future__ import annotations

import numpy as np

from wavelet_fdi.statistics import CusumBank, energy_reference


def lindley(z: np.ndarray) -> tuple[np.ndarray, int]:
    s, out, last = 0.0, [], -1
    for i, v in enumerate(z):
        s = max(0.0, s + v)
        out.append(s)
        if s == 0.0:
            last = i
    return np.array(out), last


def test_matches_the_scalar_recursion_and_tracks_the_last_zero():
    z = np.random.default_rng(0).standard_normal((3, 2000)) * 0.7 - 0.2
    bank = CusumBank(3)
    s = bank.update(z, 0)
    for row in range(3):
        ref, last = lindley(z[row])
        np.testing.assert_allclose(s[row], ref, atol=1e-9)
        assert bank.last_zero[row] == last


def test_chunks_and_renormalisation_are_exact():
    z = np.random.default_rng(1).standard_normal((2, 999)) - 0.3
    whole = CusumBank(2)
    s_whole = whole.update(z, 0)
    for chunk in (1, 7, 64):
        bank = CusumBank(2)
        parts = [bank.update(z[:, a:a + chunk], a) for a in range(0, 999, chunk)]
        assert np.array_equal(np.hstack(parts), s_whole)
        assert np.array_equal(bank.last_zero, whole.last_zero)
    bank = CusumBank(2)
    bank.update(z[:, :500], 0)
    before = bank.value.copy()
    bank.renormalise()
    assert np.array_equal(bank.value, before)
    assert np.all(bank.m == 0.0)


def test_energy_reference_is_the_variance_llr_balance_point():
    # the increment u^2 - k has zero mean at the geometric-mean-like point between 1 and rho
    k = energy_reference(4.0)
    assert 1.0 < k < 4.0
    assert abs(k - np.log(4.0) / 0.75) < 1e-12
