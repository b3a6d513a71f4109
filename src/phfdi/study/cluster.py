"""Clustering of multisignal rows from their wavelet representations (MATLAB's mdwtcluster, and more).

Features of a row: its level-L approximation coefficients (``ca``, 18
numbers for 1440 samples at level 7), its (compressed) coefficients, or a
reconstructed signal. Methods: agglomerative hierarchical clustering
(:func:`scipy.cluster.hierarchy.linkage`; Ward linkage on Euclidean
distances, mdwtcluster's default) and k-means (:func:`scipy.cluster.vq.kmeans2`,
k-means++ starts, best of several restarts).

The number of clusters is given, or chosen as the one of largest mean
silhouette. Agreement between two partitions is the adjusted Rand index
(Hubert and Arabie 1985): 1 for identical partitions up to renaming, about
0 for independent ones. ARI and silhouette are written here (a contingency
table and a distance matrix each) rather than pulling in scikit-learn for
two formulas; they are tested against hand-computed cases.
"""

from __future__ import annotations

import warnings
from typing import Any, Sequence

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.cluster.vq import kmeans2
from scipy.spatial.distance import pdist, squareform
from scipy.special import comb

METHODS = ("hierarchical", "kmeans")

#: labels of a partition: any sequence of hashable labels, or an integer/string array
Labels = Sequence[Any] | np.ndarray


def hierarchical(features: np.ndarray, n_clusters: int, method: str = "ward",
                 metric: str = "euclidean") -> tuple[np.ndarray, np.ndarray]:
    """Cluster labels 0..k-1 (ordered by first row) and the linkage matrix."""
    x = np.atleast_2d(np.asarray(features, dtype=float))
    _check_k(n_clusters, len(x))
    z = linkage(x, method=method, metric=metric)
    return canonical(fcluster(z, t=n_clusters, criterion="maxclust")), z


def kmeans(features: np.ndarray, n_clusters: int, seed: int = 0, restarts: int = 10) -> np.ndarray:
    """k-means labels 0..k-1 (ordered by first row): the restart of least within-cluster sum of squares."""
    x = np.atleast_2d(np.asarray(features, dtype=float))
    _check_k(n_clusters, len(x))
    rng = np.random.default_rng(seed)
    best, best_inertia = None, np.inf
    for _ in range(restarts):
        with warnings.catch_warnings():  # an empty cluster is handled below, not worth a warning
            warnings.simplefilter("ignore", UserWarning)
            centroids, labels = kmeans2(x, n_clusters, minit="++", seed=rng)
        inertia = float(np.sum((x - centroids[labels]) ** 2))
        if inertia < best_inertia and len(np.unique(labels)) == n_clusters:
            best, best_inertia = labels, inertia
    if best is None:  # every restart left a cluster empty (duplicate rows): take the last
        best = labels
    return canonical(best)


def cluster(features: np.ndarray, n_clusters: int, method: str = "hierarchical", seed: int = 0) -> np.ndarray:
    if method == "hierarchical":
        return hierarchical(features, n_clusters)[0]
    if method == "kmeans":
        return kmeans(features, n_clusters, seed=seed)
    raise ValueError(f"unknown clustering method {method!r}; use one of {', '.join(METHODS)}")


def _check_k(k: int, n: int) -> None:
    if not 1 <= k <= n:
        raise ValueError(f"cannot make {k} clusters of {n} rows")


def canonical(labels: Labels) -> np.ndarray:
    """Relabel 0, 1, ... in order of first appearance (so equal partitions have equal labels)."""
    items = list(labels)
    first = {lab: i for i, lab in reversed(list(enumerate(items)))}
    order = sorted(first, key=first.__getitem__)
    code = {lab: i for i, lab in enumerate(order)}
    return np.array([code[lab] for lab in items], dtype=int)


def adjusted_rand_index(a: Labels, b: Labels) -> float:
    """Adjusted Rand index of two partitions of the same items (Hubert and Arabie 1985).

    ARI = (sum_ij C(n_ij, 2) - E) / (max - E), with n_ij the contingency
    table, E = sum_i C(a_i, 2) sum_j C(b_j, 2) / C(n, 2) and
    max = (sum_i C(a_i, 2) + sum_j C(b_j, 2)) / 2.
    """
    code_a, code_b = canonical(a), canonical(b)
    if len(code_a) != len(code_b):
        raise ValueError(f"partitions of {len(code_a)} and {len(code_b)} items")
    n = len(code_a)
    table = np.zeros((code_a.max() + 1, code_b.max() + 1))
    np.add.at(table, (code_a, code_b), 1)
    sum_ij = comb(table, 2).sum()
    sum_a = comb(table.sum(axis=1), 2).sum()
    sum_b = comb(table.sum(axis=0), 2).sum()
    expected = sum_a * sum_b / comb(n, 2)
    maximum = 0.5 * (sum_a + sum_b)
    if maximum == expected:  # both partitions trivial (all one cluster or all singletons)
        return 1.0
    return float((sum_ij - expected) / (maximum - expected))


def silhouette(features: np.ndarray, labels: Labels) -> float:
    """Mean silhouette (Rousseeuw 1987): (b - a) / max(a, b) per row, 0 for rows alone in their cluster."""
    x = np.atleast_2d(np.asarray(features, dtype=float))
    codes = canonical(labels)
    k = codes.max() + 1
    if not 2 <= k <= len(x) - 1:
        raise ValueError(f"silhouette needs 2..{len(x) - 1} clusters, got {k}")
    d = squareform(pdist(x))
    s = np.zeros(len(x))
    for i in range(len(x)):
        own = codes == codes[i]
        if own.sum() == 1:
            continue
        a = d[i, own].sum() / (own.sum() - 1)
        b = min(d[i, codes == c].mean() for c in range(k) if c != codes[i])
        s[i] = (b - a) / max(a, b) if max(a, b) > 0 else 0.0
    return float(s.mean())


def choose_n_clusters(features: np.ndarray, k_range: Sequence[int] = range(2, 9),
                      method: str = "hierarchical", seed: int = 0) -> tuple[int, dict[int, float]]:
    """Number of clusters of largest mean silhouette, and the silhouette of each k tried."""
    n = len(np.atleast_2d(features))
    scores = {k: silhouette(features, cluster(features, k, method, seed)) for k in k_range if 2 <= k <= n - 1}
    if not scores:
        raise ValueError(f"no number of clusters to choose from for {n} rows")
    return max(scores, key=scores.__getitem__), scores


def contingency(clusters: Labels, labels: Sequence[str]) -> tuple[list[str], np.ndarray]:
    """Rows per (cluster, class): the classes in order of appearance and the (k, n_classes) counts."""
    classes = list(dict.fromkeys(labels))
    codes = canonical(clusters)
    table = np.zeros((codes.max() + 1, len(classes)), dtype=int)
    for c, lab in zip(codes, labels):
        table[c, classes.index(lab)] += 1
    return classes, table
