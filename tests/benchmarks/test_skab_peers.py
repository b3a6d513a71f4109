"""The peer change detectors under the SKAB protocol, on the learned reference's residuals: a synthetic step."""

import numpy as np
import pytest

from phfdi.benchmarks import skab
from wavelet_fdi.peers import PEERS, Peer, hold_states, multichannel_states

TRAIN, TEST, ONSET = 400, 400, 150  # the step starts at test row ONSET
# Thresholds come from 400 healthy rows (a tail fit of 56 window maxima extrapolated to a 1e4-sample ARL0):
# on white noise about one 150-row healthy stretch in four still gets a false alarm from some peer, so the
# record is one fixed seed (2: seeds 0 and 1 give ADWIN resp. all four an alarm in those rows); what can
# fail is the adapter (silent before the step, causal, detecting, holding).


def record(seed: int = 2, step_sigma: float = 3.0, channel: int = 3):
    """8 independent noisy channels around different levels; a mean step on one channel after ONSET."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 1.0, (TRAIN + TEST, 8)) * np.arange(1, 9) + 10.0 * np.arange(8)
    x[TRAIN + ONSET:, channel] += step_sigma * (channel + 1)
    return x[:TRAIN], x[TRAIN:], np.arange(TEST, dtype=float)


@pytest.mark.parametrize("name", PEERS)
def test_peer_silent_before_the_step_and_detects_it(name):
    train, test, t = record()
    pred = skab.peer_detector(name)(train, test, t)
    assert pred.shape == (TEST,) and set(np.unique(pred)) <= {0, 1}
    assert not pred[:ONSET].any(), f"{name} alarmed before the step at row {np.flatnonzero(pred)[0]}"
    hit = np.flatnonzero(pred[ONSET:])
    assert len(hit) and hit[0] < 60, f"{name} missed the step (first alarm {hit[:1]})"
    if name in ("cusum", "focus"):  # they test against the healthy mean: a lasting step keeps them alarming
        assert pred[ONSET:].mean() > 0.9
    else:  # Page-Hinkley and ADWIN follow the new mean: one alarm (held block_samples rows) per change
        assert 0.05 < pred[ONSET:].mean() < 0.7


@pytest.mark.parametrize("name", PEERS)
def test_peer_is_causal(name):
    train, test, t = record()
    det = skab.peer_detector(name)
    a = det(train, test, t)
    b = det(train, test[:ONSET + 20], t[:ONSET + 20])
    assert np.array_equal(a[:ONSET + 20], b)  # later rows do not change earlier predictions


def test_hold_and_union_of_channels():
    assert hold_states([2, 4], 10, 3).tolist() == [0, 0, 1, 1, 1, 1, 1, 0, 0, 0]
    u = np.zeros((200, 3))
    u[100:, 2] = 4.0
    st = multichannel_states(Peer("cusum", 10.0, 0.5), u, 5)
    assert not st[:100].any() and st[105:].all()
