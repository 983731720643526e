"""``make bench``: every benchmark measures darkread next to a reference measured in the same run.

Each module in this package defines ``run(ctx: BenchContext) -> list[Figure]``. The runner prints
one table and writes ``bench.json`` (one key per figure, the unit in the key). ``ctx.smoke`` asks
for the smallest inputs and a single repetition: every figure is produced, none is meaningful
(``tests/bench`` runs each benchmark that way and checks the keys it writes).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Benchmark modules, in the order of the data flow.
BENCH_MODULES: tuple[str, ...] = (
    "darkread.bench.decode",
    "darkread.bench.fovea",
    "darkread.bench.gaze",
    "darkread.bench.synth",
    "darkread.bench.inference",
    "darkread.bench.edge",
    "darkread.bench.cloud",
    "darkread.bench.ask",
    "darkread.bench.speech",
    "darkread.bench.stitch",
    "darkread.bench.ocr",
)


@dataclass(frozen=True)
class Figure:
    """One measured figure. ``key`` carries the unit (e.g. ``decode_mev_per_s``)."""

    key: str
    value: float
    label: str
    reference: str = ""  # what it is compared with, e.g. "evt3 0.4.1: 58.1 Mev/s"
    goal: str = ""  # the stated goal, e.g. ">= 0.5x"


@dataclass
class BenchContext:
    """What a benchmark may use: where the shared data lives (if any) and a scratch folder."""

    shared_data: Path | None
    scratch: Path
    quick: bool = False
    smoke: bool = False  # tiny inputs, one repetition: checks that every figure is made, not its value
    notes: list[str] = field(default_factory=list)

    def runs(self, full: int, quick: int, smoke: int = 1) -> int:
        """How many repetitions (or how large an input) for the chosen mode."""
        return smoke if self.smoke else quick if self.quick else full


def best_median_s(call: Callable[[], object], runs: int, repeats: int = 3, warmup: int = 5) -> float:
    """Best of ``repeats`` medians of ``runs`` timed calls, in seconds.

    The host may be shared: the best median is the figure that repeats from run to run.
    """
    for _ in range(warmup):
        call()
    best = float("inf")
    for _ in range(repeats):
        times = np.empty(runs)
        for i in range(runs):
            start = time.perf_counter()
            call()
            times[i] = time.perf_counter() - start
        best = min(best, float(np.median(times)))
    return best
