"""Clustering: ARI and silhouette by hand, and recovery of a known grouping of synthetic signals."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.study import cluster
from phfdi.study.compress import compress_energy
from phfdi.study.multisignal import decompose


def test_adjusted_rand_index_hand_case():
    # contingency [[2, 0, 0], [0, 1, 1]]: sum C(nij,2) = 1, rows 2, columns 1, E = 2 * 1 / 6,
    # max = 1.5 -> ARI = (1 - 1/3) / (1.5 - 1/3) = 4/7
    assert cluster.adjusted_rand_index([0, 0, 1, 1], [0, 0, 1, 2]) == pytest.approx(4 / 7)


def test_adjusted_rand_index_properties():
    a = [0, 0, 1, 1, 2, 2, 2]
    assert cluster.adjusted_rand_index(a, ["x", "x", "y", "y", "z", "z", "z"]) == pytest.approx(1.0)
    b = [1, 0, 0, 2, 1, 2, 0]
    assert cluster.adjusted_rand_index(a, b) == pytest.approx(cluster.adjusted_rand_index(b, a))
    rng = np.random.default_rng(0)
    scores = [cluster.adjusted_rand_index(rng.integers(0, 3, 200), rng.integers(0, 3, 200)) for _ in range(20)]
    assert abs(np.mean(scores)) < 0.02  # chance level is 0


def test_silhouette_hand_case():
    # points 0, 1 | 10, 11: s = (10.5 - 1) / 10.5 for the outer, (9.5 - 1) / 9.5 for the inner points
    x = np.array([[0.0], [1.0], [10.0], [11.0]])
    expected = (2 * (9.5 / 10.5) + 2 * (8.5 / 9.5)) / 4
    assert cluster.silhouette(x, [0, 0, 1, 1]) == pytest.approx(expected)


def _three_shapes(rng, per_class=8, n=1024):
    t = np.linspace(0, 1, n)
    shapes = {"slow sine": np.sin(2 * np.pi * t), "step": np.where(t > 0.5, 1.0, -1.0),
              "fast wobble": 0.3 * np.sin(2 * np.pi * 40 * t)}
    rows, labels = [], []
    for name, s in shapes.items():
        for _ in range(per_class):
            rows.append(s * rng.uniform(0.8, 1.2) + 0.15 * rng.normal(size=n))
            labels.append(name)
    return np.array(rows), labels


@pytest.mark.parametrize("method", cluster.METHODS)
def test_recovers_a_known_grouping_from_compressed_wavelet_coefficients(method):
    x, labels = _three_shapes(np.random.default_rng(7))
    order = np.random.default_rng(8).permutation(len(labels))  # classes not in blocks
    x, labels = x[order], [labels[i] for i in order]
    dec = decompose(x, "sym4", 5)
    feats = compress_energy(dec, 0.99).decomposition.flat()
    found = cluster.cluster(feats, 3, method)
    assert cluster.adjusted_rand_index(found, labels) == pytest.approx(1.0)
    k, scores = cluster.choose_n_clusters(feats, range(2, 7), method)
    assert k == 3 and scores[3] == max(scores.values())


def test_contingency_and_canonical_labels():
    assert cluster.canonical([5, 5, 2, 9, 2]).tolist() == [0, 0, 1, 2, 1]
    classes, table = cluster.contingency([1, 1, 0, 0], ["a", "b", "b", "b"])
    assert classes == ["a", "b"] and table.tolist() == [[1, 1], [0, 2]]
    with pytest.raises(ValueError):
        cluster.cluster(np.zeros((3, 2)), 4)


def test_spearman_hand_cases():
    from phfdi.study.analysis import spearman

    # ranks (0,1,2,3) vs (0,1,3,2): rho = 1 - 6 * 2 / (4 * 15) = 0.8
    assert spearman([1, 2, 3, 4], [10, 20, 40, 30]) == pytest.approx(0.8)
    assert spearman([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    # ties share their mean rank: y ranks (0.5, 0.5, 2) -> Pearson with (0, 1, 2) = 0.866
    assert spearman([1, 2, 3], [5, 5, 9]) == pytest.approx(np.sqrt(3) / 2)
