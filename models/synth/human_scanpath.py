"""Real readers' fixation sequences replayed on a synthetic page.

A human scanpath is stored on its passage's character grid: per fixation the printed line, the
position along that line as a fraction of its characters, the vertical offset from the line's
centre in line pitches (the tracker's drift and the reader's own scatter) and the duration. On a
synthetic page, source line ``L`` lands on page line ``L mod n_lines`` (a longer passage re-reads
the page from the top) at the same fraction of that line's characters and the same offset in
pitches, so regressions, skips, re-reading, return-sweep undershoot and vertical drift are kept;
saccades between fixations are shaped by the reading model (main sequence, minimum jerk).

Shipped: ``data/human_scanpath_oz.json``, derived from EyeLink's fixations of one reader of "Little
Wizard Stories of Oz" (Slattery & Vasilev 2019, MIT licence, see the file's ``license``).
The lab derives the same form from the drift (CC BY 4.0; not shipped) and oz data under
``../shared/data/reading_gaze`` (``darkread.lab.gaze.scanpaths``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.models.synth.gaze import Fixation, Scanpath, saccade_ms, trajectory
from darkread.models.synth.page import PrintedPage

SHIPPED = Path(__file__).with_name("data") / "human_scanpath_oz.json"


@dataclass(frozen=True)
class HumanScanpath:
    line: np.ndarray  # int: printed line of the source passage
    frac: np.ndarray  # position along the line, fraction of its characters (0 = first character)
    dy_pitch: np.ndarray  # vertical offset from the line centre, in line pitches
    duration_ms: np.ndarray
    source: str = ""

    def to_json(self) -> dict:
        rows = [[int(a), round(float(b), 4), round(float(c), 3), int(round(float(d)))]
                for a, b, c, d in zip(self.line, self.frac, self.dy_pitch, self.duration_ms)]
        return {"source": self.source, "columns": ["line", "frac", "dy_pitch", "duration_ms"], "fixations": rows}

    @staticmethod
    def load(path: str | Path = SHIPPED) -> HumanScanpath:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
        rows = np.asarray(doc["fixations"], dtype=np.float64).reshape(-1, 4)
        if rows.shape[0] == 0:
            raise ValueError(f"{path}: no fixations")
        return HumanScanpath(rows[:, 0].astype(np.int64), rows[:, 1], rows[:, 2], rows[:, 3], str(doc.get("source", path)))


def _kind(prev_line: int, line: int, prev_char: float, char: float, first: bool) -> str:
    if first:
        return "start"
    if line != prev_line:
        return "sweep" if line > prev_line or (line == 0 and prev_line > 0) else "regression"
    return "forward" if char >= prev_char else "regression"


def replay_scanpath(page: PrintedPage, human: HumanScanpath, duration_s: float, deg_per_texel: float,
                    rng: np.random.Generator, dt_s: float = 0.001) -> Scanpath:
    """A scanpath over ``page`` lasting at least ``duration_s``: ``human`` replayed (and looped)."""
    n_lines = len(page.lines)
    pitch = float(np.median(np.diff(page.line_y))) if n_lines > 1 else 2.0 * page.xheight_tex
    fixations: list[Fixation] = []
    saccades: list[tuple[float, float]] = []
    t = 0.0
    k = 0
    src_line0 = int(human.line.min())
    while t < duration_s:
        i = k % len(human.line)
        line = int(human.line[i] - src_line0) % n_lines
        cx = page.char_x[line]
        n = len(cx)
        char = float(np.clip(human.frac[i], -0.05, 1.05)) * n
        step = float(np.diff(cx).mean()) if n > 1 else page.xheight_tex
        x = float(np.interp(char, np.arange(n), cx, left=cx[0] + char * step, right=cx[-1] + (char - n + 1) * step))
        y = float(page.line_y[line] + human.dy_pitch[i] * pitch)
        if fixations:
            prev = fixations[-1]
            amp = math.hypot(x - prev.x, y - prev.y) * deg_per_texel
            kind = _kind(prev.line, line, prev.char, char, False)
            sd = saccade_ms(amp, forward=(kind == "forward")) / 1000.0
            saccades.append((t, sd))
            t += sd
        else:
            kind = "start"
        dur = float(human.duration_ms[i]) / 1000.0
        fixations.append(Fixation(t, t + dur, line, char, x, y, kind))
        t += dur
        k += 1
    return trajectory(fixations, saccades, t, rng, dt_s)
