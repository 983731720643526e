"""Is a decoded RAW stream what its header says? Cheap checks on the decoder's counters and on
event time, so corrupt input is named instead of decoded into nonsense without a word.

The decoder already counts what it could not use (``DecodeStats``); a healthy EVT 3.0 recording
has none of it. A wrong format in the header (EVT 2.0 words read as EVT 3.0, or the reverse),
garbage appended to a file, a header declaring a smaller sensor than the data, and a clock that
jumps by minutes all show up as one of these shares. Vectorised: one ``np.diff`` per chunk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darkread.edge.io.word_stream import DecodeStats

MAX_UNDECODABLE_SHARE = 0.001  # of the words: backward TIME_HIGH and the events dropped after one
MAX_BACKWARD_TIME_STEPS = 100  # a sensor's clock never runs back; a few are tolerated (a USB glitch)
MAX_OTHER_SHARE = 0.25  # of the words: OTHERS/CONTINUED/reserved (real IMX636 streams carry ERC counters: 7 %)
MAX_OUT_OF_GEOMETRY_SHARE = 0.001  # of the events: pixels beyond the declared width/height
MAX_TIME_JUMP_US = 60_000_000  # an event camera never goes a minute without an event or TIME_HIGH


@dataclass
class TimeCheck:
    """Largest forward step of event time seen so far, across chunks."""

    last_t: int | None = None
    max_jump_us: int = 0
    jump_at_us: int = 0

    def add(self, t: np.ndarray) -> None:
        """The steps into and within ``t`` (a replay calls this per 1-ms slice: no copies beyond one difference)."""
        if t.shape[0] == 0:
            return
        first = int(t[0])
        if self.last_t is not None and first - self.last_t > self.max_jump_us:
            self.max_jump_us, self.jump_at_us = first - self.last_t, first
        if t.shape[0] > 1:
            steps = t[1:] - t[:-1]
            i = int(steps.argmax())
            if int(steps[i]) > self.max_jump_us:
                self.max_jump_us, self.jump_at_us = int(steps[i]), int(t[i + 1])
        self.last_t = int(t[-1])


def problems(stats: DecodeStats, fmt: str, width: int, height: int, time: TimeCheck) -> list[str]:
    """What makes this stream implausible, one sentence each (empty: it looks like its header)."""
    found = []
    undecodable = stats.skipped_other + stats.non_monotonic_time_high + stats.dropped_non_monotonic
    backward = stats.non_monotonic_time_high + stats.dropped_non_monotonic
    if stats.words and (
        backward / stats.words > MAX_UNDECODABLE_SHARE
        or stats.non_monotonic_time_high > MAX_BACKWARD_TIME_STEPS
        or stats.skipped_other / stats.words > MAX_OTHER_SHARE
    ):
        found.append(
            f"{undecodable / stats.words:.1%} of the data does not decode as {fmt} ({stats.non_monotonic_time_high:,} "
            f"backward time steps, {stats.dropped_non_monotonic + stats.skipped_other:,} unusable words): a wrong "
            "format in the header, or garbage in the file"
        )
    seen = stats.events + stats.events_out_of_range
    if seen and stats.events_out_of_range / seen > MAX_OUT_OF_GEOMETRY_SHARE:
        found.append(
            f"{stats.events_out_of_range:,} of {seen:,} events lie outside the declared {width}x{height} geometry "
            "(dropped): the header's size is wrong"
        )
    if time.max_jump_us > MAX_TIME_JUMP_US:
        found.append(f"event time jumps by {time.max_jump_us / 1e6:,.0f} s at t={time.jump_at_us / 1e6:,.1f} s")
    return found
