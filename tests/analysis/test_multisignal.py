"""Row decomposition (mdwtdec/mdwtrec): shapes, MATLAB agreement, perfect reconstruction, resampling."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import pywt

from phfdi.study.multisignal import Multisignal, decompose, from_runs, pywt_mode, reconstruction_error, resample_mean


def matlab_length(n: int, filter_length: int) -> int:
    """MATLAB's wavedec coefficient count per level in 'sym' mode: floor((n + L - 1) / 2)."""
    return (n + filter_length - 1) // 2


def test_paper_shapes_35_by_1440_sym4_level7():
    x = np.random.default_rng(0).normal(size=(35, 1440))
    dec = decompose(x, "sym4", 7, "sym")
    assert dec.ca.shape == (35, 18)  # the paper's "ca: [35x18 double]"
    assert len(dec.cd) == 7
    n, expected = 1440, []
    for _ in range(7):
        n = matlab_length(n, 8)
        expected.append(n)
    assert [d.shape for d in dec.cd] == [(35, m) for m in expected]
    assert dec.lengths() == [18] + expected[::-1] + [1440]


def _matlab_sym4_data():
    """The inputs PyWavelets' own MATLAB-compatibility test drew (same generator, same order)."""
    rs = np.random.RandomState(1234)
    out = {}
    for name in sum([pywt.wavelist(f) for f in ("db", "sym", "coif", "bior", "rbio")], []):
        w = pywt.Wavelet(name)
        for n in (w.dec_len, w.dec_len + 1):
            x = rs.randn(n)
            if name == "sym4":
                out[n] = x
    return out


def test_level1_coefficients_equal_matlab_r2012a_sym_mode():
    from pywt._pytest import matlab_result_dict_dwt as matlab

    if matlab is None or "sym_sym4_8_ma" not in getattr(matlab, "files", []):
        pytest.skip("PyWavelets' stored MATLAB results are not installed")
    for n, x in _matlab_sym4_data().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # level 1 on 8 samples: all boundary
            dec = decompose(x[None, :], "sym4", 1, "sym")
        np.testing.assert_allclose(dec.ca[0], np.ravel(matlab[f"sym_sym4_{n}_ma"]), atol=1e-12)
        np.testing.assert_allclose(dec.cd[0][0], np.ravel(matlab[f"sym_sym4_{n}_md"]), atol=1e-12)


@pytest.mark.parametrize("wavelet,level,mode", [("sym4", 7, "sym"), ("db8", 3, "symmetric"),
                                                 ("haar", 5, "per"), ("coif2", 4, "zpd")])
def test_perfect_reconstruction(wavelet, level, mode):
    x = np.random.default_rng(1).normal(size=(6, 1000)).cumsum(axis=1)
    dec = decompose(x, wavelet, level, mode)
    assert reconstruction_error(dec, x) < 1e-9 * np.max(np.abs(x))


def test_approximations_and_details_add_up_like_mdwtrec():
    x = np.random.default_rng(2).normal(size=(3, 700)).cumsum(axis=1)
    dec = decompose(x, "sym4", 5)
    total = dec.approximation(5) + sum(dec.detail(j) for j in range(1, 6))
    np.testing.assert_allclose(total, x, atol=1e-9)
    for k in range(1, 5):
        np.testing.assert_allclose(dec.approximation(k), dec.approximation(k + 1) + dec.detail(k + 1), atol=1e-9)
    np.testing.assert_allclose(dec.approximation(0), x, atol=1e-9)


def test_flat_round_trip_and_bad_arguments():
    x = np.random.default_rng(3).normal(size=(2, 300))
    dec = decompose(x, "sym4", 4)
    back = dec.unflat(dec.flat())
    np.testing.assert_array_equal(back.reconstruct(), dec.reconstruct())
    with pytest.raises(ValueError, match="out of range"):
        decompose(x, "sym4", 9)
    with pytest.raises(ValueError, match="extension mode"):
        pywt_mode("mirror")
    with pytest.raises(ValueError):
        dec.approximation(5)


def test_resample_mean_is_the_bin_average():
    t = np.arange(0.0, 100.0 + 1e-9, 1.0)
    edges = np.linspace(0.0, 100.0, 11)
    np.testing.assert_allclose(resample_mean(t, 3.0 + 0 * t, edges), 3.0)
    # a ramp's bin average is its value at the bin centre
    np.testing.assert_allclose(resample_mean(t, 2.0 * t, edges), 2.0 * (edges[:-1] + 5.0))
    # non-uniform, unsorted time stamps and a NaN sample
    tt = np.array([0.0, 30.0, 10.0, 100.0, 55.0, np.nan])
    xx = 2.0 * np.nan_to_num(tt)
    np.testing.assert_allclose(resample_mean(tt, xx, np.array([0.0, 50.0, 100.0])), [50.0, 150.0])


class _FakeRun:
    def __init__(self, t, **signals):
        self.signals = {"time_s": t, **signals}
        self.time_s = t

    def __getitem__(self, name):
        return self.signals[name]

    def __contains__(self, name):
        return name in self.signals


def test_from_runs_cuts_to_the_common_window():
    a = _FakeRun(np.arange(0.0, 101.0), ph_measured=np.full(101, 7.0), ph_true=np.full(101, 7.0))
    b = _FakeRun(np.arange(0.0, 201.0, 2.0), ph_measured=np.arange(0.0, 201.0, 2.0), ph_true=np.zeros(101))
    ms = from_runs([a, b], ["healthy", "backlash"], n_samples=10)
    assert isinstance(ms, Multisignal) and ms.shape == (2, 10)
    np.testing.assert_allclose(ms.time_s, np.arange(5.0, 100.0, 10.0))
    np.testing.assert_allclose(ms.data[1], np.arange(5.0, 100.0, 10.0))
    assert ms.unit == "pH" and ms.truth is not None
    assert ms.classes == ["healthy", "backlash"]
