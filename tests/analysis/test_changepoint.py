"""Variance change points (wvarchg): planted changes, no false changes on noise, the selection rule."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.study.changepoint import level1_details, penalty_intervals, select_n_changes, variance_change_points


def test_finds_a_planted_variance_change():
    rng = np.random.default_rng(10)
    y = np.concatenate([rng.normal(0, 1, 900), rng.normal(0, 2.5, 540)])
    r = variance_change_points(y)
    assert r.n_changes == 1
    assert abs(r.points[0] - 900) <= 10


def test_finds_two_planted_changes_and_returns_every_k():
    rng = np.random.default_rng(11)
    y = np.concatenate([rng.normal(0, 1, 700), rng.normal(0, 3, 300), rng.normal(0, 1, 440)])
    r = variance_change_points(y, max_changes=5, min_distance=10)
    assert r.n_changes == 2
    assert abs(r.points[0] - 700) <= 10 and abs(r.points[1] - 1000) <= 10
    assert [len(s) for s in r.solutions] == list(range(6))
    assert np.all(np.diff(r.contrast) <= 1e-9)  # more changes never fit worse


def test_segments_respect_the_minimum_distance():
    rng = np.random.default_rng(12)
    y = rng.normal(0, 1, 400)
    r = variance_change_points(y, max_changes=6, min_distance=25)
    for pts in r.solutions:
        edges = [0, *pts, len(y)]
        assert all(b - a >= 25 for a, b in zip(edges[:-1], edges[1:]))


@pytest.mark.parametrize("seed", range(8))
def test_no_change_on_stationary_noise(seed):
    y = np.random.default_rng(100 + seed).normal(0, 1, 1000)
    assert variance_change_points(y).n_changes == 0


def test_through_level1_details_of_a_trending_signal():
    rng = np.random.default_rng(13)
    t = np.arange(4000.0)
    x = 5 + 0.001 * t + np.sin(2 * np.pi * t / 800) + np.where(t < 2600, 0.05, 0.15) * rng.normal(size=t.size)
    det = level1_details(x)
    r = variance_change_points(det)
    assert r.n_changes == 1 and abs(2 * r.points[0] - 2600) <= 20


def test_selection_rule_hand_case():
    # J = 10, 4, 3, 2.5: hull slopes 6, 1, 0.5 -> K = 0 for beta > 6, 1 for 1..6, 2 for 0.5..1, 3 below 0.5
    intervals = penalty_intervals(np.array([10.0, 4.0, 3.0, 2.5]))
    assert intervals == {0: (6.0, np.inf), 1: (1.0, 6.0), 2: (0.5, 1.0), 3: (0.0, 0.5)}
    assert select_n_changes(np.array([10.0, 4.0, 3.0, 2.5])) == 1      # widest: 1 .. 6
    assert select_n_changes(np.array([10.0, 9.9, 9.8, 0.0])) == 0      # no intermediate K beats K_max's range
    assert select_n_changes(np.array([10.0, 4.0, 3.0, 2.5]), penalty=0.7) == 2
