"""The replay's time check: the largest forward step of event time, whatever the chunking."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.io.plausibility import TimeCheck


def whole_stream_jump(t: np.ndarray) -> tuple[int, int]:
    """The largest step and the time after it, from the whole stream at once (the first step is 0)."""
    steps = np.diff(t, prepend=t[0])
    i = int(np.argmax(steps))
    return int(steps[i]), int(t[i])


@settings(max_examples=200, deadline=None)
@given(
    deltas=st.lists(st.integers(-50, 5_000_000), min_size=1, max_size=200),
    cuts=st.lists(st.integers(0, 200), max_size=10),
)
def test_the_largest_step_does_not_depend_on_the_chunking(deltas: list[int], cuts: list[int]) -> None:
    t = np.cumsum(np.asarray(deltas, dtype=np.int64)) + 1_000  # jittering back now and then, as real sensors do
    check = TimeCheck()
    for chunk in np.split(t, sorted(c for c in cuts if c <= t.shape[0])):
        check.add(chunk)
    jump, at = whole_stream_jump(t)
    assert check.max_jump_us == jump
    if jump:  # (no forward step at all: nothing to place)
        assert check.jump_at_us == at
    assert check.last_t == int(t[-1])
