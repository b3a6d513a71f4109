"""Compression by energy retention and by thresholds (MATLAB's mswcmp)."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.study.compress import compress_energy, compress_threshold
from phfdi.study.multisignal import decompose


@pytest.fixture
def dec():
    rng = np.random.default_rng(6)
    t = np.linspace(0, 1, 1440)
    rows = [np.where(t > 0.3, 1.0, 0.0) + 0.05 * rng.normal(size=t.size),
            np.sin(2 * np.pi * 5 * t) + 0.2 * rng.normal(size=t.size),
            rng.normal(size=t.size)]
    return decompose(np.array(rows), "sym4", 7)


@pytest.mark.parametrize("retain", [0.5, 0.9, 0.99, 0.999])
def test_energy_retention_is_reached_with_the_fewest_coefficients(dec, retain):
    out = compress_energy(dec, retain)
    flat, kept = dec.flat(), out.decomposition.flat()
    for i in range(dec.n_signals):
        energy = np.sum(flat[i] ** 2)
        assert np.sum(kept[i] ** 2) >= retain * energy * (1 - 1e-12)
        assert out.energy_retained_pct[i] == pytest.approx(100 * np.sum(kept[i] ** 2) / energy)
        nz = kept[i] != 0
        # dropping the smallest kept coefficient falls short: no coefficient too many
        smallest = np.min(np.abs(kept[i][nz]))
        assert np.sum(kept[i] ** 2) - smallest ** 2 < retain * energy
        # kept coefficients are unchanged (hard) and are the largest ones
        np.testing.assert_array_equal(kept[i][nz], flat[i][nz])
        assert np.all(np.abs(flat[i][~nz]) <= smallest)
        assert out.nonzero_pct[i] == pytest.approx(100 * nz.sum() / flat.shape[1])


def test_white_noise_needs_many_more_coefficients_than_a_step(dec):
    out = compress_energy(dec, 0.99)
    assert out.nonzero_pct[0] < 5 < out.nonzero_pct[2]


def test_keep_approximation(dec):
    out = compress_energy(dec, 0.5, keep_approx=True)
    np.testing.assert_array_equal(out.decomposition.ca, dec.ca)
    assert np.all(out.energy_retained_pct >= 50)


def test_global_and_level_thresholds(dec):
    out = compress_threshold(dec, 0.3)
    for d, k in zip(dec.cd, out.decomposition.cd):
        assert np.all(k[np.abs(d) < 0.3] == 0)
        np.testing.assert_array_equal(k[np.abs(d) >= 0.3], d[np.abs(d) >= 0.3])
    np.testing.assert_array_equal(out.decomposition.ca, dec.ca)
    per_level = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    out = compress_threshold(dec, per_level)
    for thr, d, k in zip(per_level, dec.cd, out.decomposition.cd):
        assert np.all(k[np.abs(d) < thr] == 0) and np.all(k[np.abs(d) >= thr] == d[np.abs(d) >= thr])
    with pytest.raises(ValueError, match="one per detail level"):
        compress_threshold(dec, [0.1, 0.2])
    with pytest.raises(ValueError, match="retain"):
        compress_energy(dec, 1.5)
