"""The quantisation fit's boundary grid on an OP held at values a rounding error apart.

Found on a simulated healthy loop answering load steps (domain generator, development seed 35107, loop 1479):
`phfdi loop-diagnose` stopped with scipy's "attempt to get argmin of an empty sequence". Its OP sat at one value
for most of the record, and the quantiles the boundary grid is spaced by differed by 1e-15 (a rounding error),
so every point of the fine grid rounded to one value and brute had nothing to search.
"""

from __future__ import annotations

import numpy as np

from phfdi.loopdiag.hammerstein import Problem, fit_quantization
from phfdi.loopdiag.identify import Split


def test_a_held_op_whose_quantiles_differ_by_a_rounding_error_is_fitted():
    v = 20.33031121904543
    ulp = float(np.spacing(v))
    n_train = 600
    # the training part: OP at v for over half of it, at v + ulp for a twelfth, then a ramp; the boundary grid is
    # spaced by the median step between 13 quantiles: six steps of 0 and one of ulp in the middle, i.e. ulp / 2
    op_train = np.concatenate([np.full(320, v), np.full(50, v + ulp), np.linspace(20.5, 33.6, n_train - 370)])
    op = np.concatenate([op_train, np.linspace(33.6, 21.0, 150)])
    steps = np.diff(np.quantile(op_train, np.linspace(0.05, 0.95, 13)))
    assert 0.0 < float(np.median(steps)) < ulp  # the case: a positive step below OP's resolution
    rng = np.random.default_rng(3)
    pv = np.empty_like(op)
    pv[0] = op[0]
    for k in range(1, len(op)):  # a first-order lag of OP, plus noise
        pv[k] = 0.8 * pv[k - 1] + 0.2 * op[k - 1]
    pv += rng.normal(0.0, 0.05, len(op))
    p = Problem(op, pv, 1.0, Split(len(op), n_train), False, True, 1)
    fit = fit_quantization(p)
    assert fit.cause == "quantization"
    assert np.isfinite(fit.parameters["step_pct"]) and fit.parameters["step_pct"] > 0.0
