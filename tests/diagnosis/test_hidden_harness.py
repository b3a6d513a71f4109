"""The retry rule of the seeded hidden-effect tests: each draw is independent, or the rule is not the rule.

A suite run fails by chance with probability p^3 only if draws 2 and 3 can pass where draw 1 failed. A CI run
failed because draws 2 and 3 met the report folder draw 1 had written (``diagnose`` refuses to overwrite it), so
every draw after a chance failure failed for a reason that had nothing to do with the method.
"""

from __future__ import annotations

import numpy as np
import pytest
from hidden_cases import HIDDEN_DRAWS, fresh_draws


@pytest.mark.skipif(HIDDEN_DRAWS < 2, reason="PHFDI_HIDDEN_DRAWS=1 takes one draw only")
def test_each_draw_gets_its_own_empty_folder_and_its_own_stream(tmp_path):
    seen: list[tuple[object, float, list[str]]] = []

    @fresh_draws
    def flaky(hidden_rng, tmp_path):
        seen.append((tmp_path, float(hidden_rng.random()), sorted(p.name for p in tmp_path.iterdir())))
        (tmp_path / "report").mkdir()  # what a diagnose run leaves behind
        if len(seen) < 2:
            raise AssertionError("a chance failure of the first draw")
        return "passed"

    assert flaky(hidden_rng=np.random.default_rng(5), tmp_path=tmp_path) == "passed"
    assert len(seen) == 2
    (first_dir, first_u, first_files), (second_dir, second_u, second_files) = seen
    assert first_dir != second_dir and first_files == [] and second_files == []
    assert first_u != second_u


def test_a_draw_that_always_fails_reports_every_draw(tmp_path):
    @fresh_draws
    def broken(hidden_rng, tmp_path):
        raise AssertionError(f"no effect found in {tmp_path.name}")

    with pytest.raises(AssertionError) as err:
        broken(hidden_rng=np.random.default_rng(5), tmp_path=tmp_path)
    lines = str(err.value).splitlines()
    assert lines[0] == "every draw failed:" and len(lines) == 1 + HIDDEN_DRAWS
    assert all(f"draw{k + 1}" in lines[1 + k] for k in range(HIDDEN_DRAWS))
