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
``from_drift`` and ``from_eyelink_asc`` derive the same form from the drift (CC BY 4.0; not shipped)
and oz data under ``../shared/data/reading_gaze``.
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


def from_grid(x: np.ndarray, y: np.ndarray, dur_ms: np.ndarray, line: np.ndarray, line_x0: np.ndarray,
              line_centre: np.ndarray, line_chars: np.ndarray, char_w: float, pitch: float, source: str) -> HumanScanpath:
    """Fixations in screen pixels + the source's line geometry -> the character-grid form."""
    line = np.asarray(line, dtype=np.int64)
    frac = (np.asarray(x) - line_x0[line]) / char_w / np.maximum(line_chars[line], 1)
    dy = (np.asarray(y) - line_centre[line]) / pitch
    first = int(np.argmax(line == line.min()))  # before it: the fixation cross, not reading
    return HumanScanpath(line[first:], frac[first:], dy[first:], np.asarray(dur_ms, dtype=np.float64)[first:], source)


def from_drift(fixations_json: str | Path, gold_json: str | Path, passages_json: str | Path, trial_id: str) -> HumanScanpath:
    """One drift trial: lines from the human gold standard (discarded fixations dropped), raw y
    kept as the offset, so the reader's vertical drift is replayed."""
    from darkread.gaze import human

    passages = human.load_passages(passages_json)
    trial = human.load_fixation_trials(fixations_json)[trial_id]
    gold = human.load_fixation_trials(gold_json)[trial_id]
    p = passages[trial.passage_id]
    lines = human.gold_lines(gold, p)
    keep = lines >= 0
    n = len(p.lines)
    return from_grid(trial.x[keep], trial.y[keep], (trial.end_ms - trial.start_ms)[keep], lines[keep],
                     np.full(n, p.x0), p.y0 + p.line_h * np.arange(n) - 0.2 * p.font_size,
                     np.array([len(t) for t in p.lines]), p.char_w, p.line_h, f"drift {trial_id} (passage {p.passage_id})")


def from_eyelink_asc(path: str | Path) -> HumanScanpath:
    """EyeLink's own fixations of an ASC trial with REGION CHAR boxes; line = nearest line centre."""
    from darkread.gaze import human

    raw = human.load_eyelink_asc(path)
    boxes = np.array([c[1:] for c in raw.chars], dtype=np.float64)
    tops = np.unique(boxes[:, 1])
    tops = tops[[np.sum(boxes[:, 1] == t) > 5 for t in tops]]  # printed lines, not stray boxes
    centre = tops + (boxes[0, 3] - boxes[0, 1]) / 2
    pitch = float(np.median(np.diff(tops)))
    char_w = float(np.median(boxes[:, 2] - boxes[:, 0]))
    x0 = np.array([boxes[boxes[:, 1] == t, 0].min() for t in tops])
    chars = np.array([np.sum(boxes[:, 1] == t) for t in tops])
    fx, fy = raw.fixations[:, 2], raw.fixations[:, 3]
    line = np.abs(fy[:, None] - centre[None, :]).argmin(axis=1)
    return from_grid(fx, fy, raw.fixations[:, 1] - raw.fixations[:, 0], line, x0, centre, chars, char_w, pitch,
                     f"EyeLink fixations of {Path(path).name}")


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
