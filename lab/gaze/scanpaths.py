"""Real readers' fixations (``../shared/data/reading_gaze``) in the character-grid form the simulator
replays (``darkread.models.synth.human_scanpath``): how ``data/human_scanpath_oz.json`` was made."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darkread.lab.gaze import human
from darkread.models.synth.human_scanpath import HumanScanpath


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
