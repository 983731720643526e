"""``make bench``: every benchmark measures darkread next to a reference measured in the same run.

Each module in this package defines ``run(ctx: BenchContext) -> list[Figure]``. The runner prints
one table and writes ``bench.json`` (one key per figure, the unit in the key). ``ctx.smoke`` asks
for the smallest inputs and a single repetition: every figure is produced, none is meaningful
(``tests/bench`` runs each benchmark that way and checks the keys it writes).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

# Benchmark modules, in the order of the data flow.
BENCH_MODULES: tuple[str, ...] = (
    "darkread.lab.bench.decode",
    "darkread.lab.bench.fovea",
    "darkread.lab.bench.gaze",
    "darkread.lab.bench.imu",
    "darkread.lab.bench.synth",
    "darkread.lab.bench.inference",
    "darkread.lab.bench.edge",
    "darkread.lab.bench.cloud",
    "darkread.lab.bench.ask",
    "darkread.lab.bench.speech",
    "darkread.lab.bench.stitch",
    "darkread.lab.bench.ocr",
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
    cache: Path | None = None  # kept between runs: inputs that take long to make (simulated recordings)
    notes: list[str] = field(default_factory=list)

    def runs(self, full: int, quick: int, smoke: int = 1) -> int:
        """How many repetitions (or how large an input) for the chosen mode."""
        return smoke if self.smoke else quick if self.quick else full


def cpu_seconds(pid: int) -> float:
    """User + system CPU of a process so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
