"""The physics detector's bad-input counters are named once (wavelet_fdi.inputs.INPUT_PROBLEMS): the alarm text's
input problems derive from it (issue 37: two hand-written lists, 17 and 12 names, had drifted: replay did not say a bad
level or a non-finite outlet command; the physics detector's node, which had the other list, was retired on
2026-12-07)."""

from __future__ import annotations

from phfdi.alarm_text import input_problems
from wavelet_fdi.inputs import InputRegularizer


def test_replay_says_every_declared_counter_that_grew_and_nothing_else():
    diagnostics = {c: 0 for c in InputRegularizer.COUNTERS}
    diagnostics.update(samples_used=900, gaps_bridged=3, bad_level=2, nonfinite_outlet_command=1,
                       reference_resets=1, state="ok")
    assert input_problems(diagnostics) == {"bad_level": 2, "nonfinite_outlet_command": 1, "reference_resets": 1}
