"""Blocks with ``step_many`` (the diagnosis runs a chain block by block over a record) give exactly what
``step`` gives sample by sample, from the same state, and leave the same state behind."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ph_plant_sim.feedlines import LineDelay, PumpCurve
from ph_plant_sim.sensors import Bias, Drift, FirstOrderLag, Gain, TransportDelay, TwoPointCalibration
from phfdi.diagnosis.model import _run_chain
from phfdi_base.blocks import Chain


def _blocks(delay_s: float, dt_s: float, severity: float):
    return [TransportDelay(delay_s, dt_s, severity), LineDelay(delay_s * 0.7, dt_s, severity),
            Bias(0.31, severity), Drift(-0.002, severity), Gain(1.07, 7.0, severity),
            TwoPointCalibration(0.93, -0.2, severity), PumpCurve(1.15, 0.4, severity)]


@settings(max_examples=40, deadline=None)
@given(delay_s=st.floats(0.0, 30.0), dt_s=st.sampled_from([0.35, 1.0, 2.0]), severity=st.floats(0.0, 1.0),
       n=st.integers(1, 80), split=st.integers(0, 80), seed=st.integers(0, 2**31))
def test_step_many_equals_step(delay_s, dt_s, severity, n, split, seed):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=n)) + 5.0
    t = np.arange(n) * dt_s + 3.0
    k = min(split, n)
    for a, b in zip(_blocks(delay_s, dt_s, severity), _blocks(delay_s, dt_s, severity)):
        a.reset(float(x[0]))
        b.reset(float(x[0]))
        ref = np.array([a.step(float(v), float(tk)) for v, tk in zip(x, t)])
        # in two calls: the state left by the first carries into the second
        got = np.concatenate([b.step_many(x[:k], t[:k]), b.step_many(x[k:], t[k:])])
        assert np.array_equal(ref, got), type(a).__name__


def test_run_chain_matches_the_chain_stepped_per_sample():
    rng = np.random.default_rng(3)
    x = 7.0 + np.cumsum(rng.normal(scale=0.1, size=300))
    t = (np.arange(300) * 0.35).tolist()
    # a block without step_many (the lag) between vectorised ones: its input is the delayed, biased signal
    make = lambda: Chain([TransportDelay(2.0, 0.35), FirstOrderLag(4.0, 0.35), Bias(0.2),  # noqa: E731
                          TwoPointCalibration(0.9, 0.1)])
    ref_chain = make()
    ref_chain.reset(float(x[0]))
    ref = np.array([ref_chain.step(v, tk) for v, tk in zip(x.tolist(), t)])
    got = _run_chain(make(), x, t)
    assert np.array_equal(ref, got)
    assert not np.array_equal(got, x)  # the chain does act


@pytest.mark.parametrize("block", [TransportDelay(3.0, 1.0), PumpCurve(1.2, 0.5), Drift(0.01)])
def test_step_many_empty_input(block):
    block.reset(1.0)
    assert len(block.step_many(np.zeros(0), np.zeros(0))) == 0


def test_fit_workers_run_one_blas_thread():
    """A fit worker limits BLAS to one thread (tiny matrices: a thread pool only waits, see fit.one_blas_thread)."""
    from concurrent.futures import ProcessPoolExecutor

    from phfdi.diagnosis import fit

    with ProcessPoolExecutor(1, initializer=_limit_only) as pool:
        threads = pool.submit(_blas_threads).result()
    assert threads and all(n == 1 for n in threads)
    with fit.one_blas_thread():
        assert all(n == 1 for n in _blas_threads())


def _limit_only():
    from phfdi.diagnosis import fit

    fit.limit_worker_blas()  # what init_worker does before building its Fitter


def _blas_threads() -> list[int]:
    import numpy  # noqa: F401  (loads numpy's BLAS)
    import scipy.linalg  # noqa: F401  (and scipy's)
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
