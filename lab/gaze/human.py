"""Real human reading gaze: readers of the drift (fixations + gold lines) and oz (raw samples) data.

Formats as described in ``../shared/data/reading_gaze/README.md``:

- drift: ``{"trial_id": {"passage_id", "fixations": {"__FixationSequence__": [{"x", "y", "start",
  "end", ["discarded"]}, ...]}}}`` in screen pixels and ms; passages ``{"id": {"__TextBlock__":
  {"position": [x0, y0], "font_size", "line_height", "text": [...]}}}`` (monospaced Courier New).
- oz: an EyeLink ASC file: ``MSG <t> REGION CHAR <i> 1 <c> <x0> <y0> <x1> <y1>`` lines, samples
  ``<t> <x> <y> <pupil> ...`` (``.`` while the tracker lost the eye) and ``EFIX``/``ESACC``/``EBLINK``.

Also the tracker noise the glasses add (``aria_like_noise``) and resampling to Aria's rates, so real
1000 Hz recordings can stand in for what the glasses deliver.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

COURIER_ADVANCE = 0.6  # Courier New: every glyph advances 0.6 em
LETTERS_PER_DEG = 3.5  # reading distance: ~3-4 letters per degree (aria-gaze.md section 4)


@dataclass(frozen=True)
class Passage:
    """A monospaced text block: first line's position, character advance and line pitch (px)."""

    passage_id: str
    x0: float
    y0: float
    font_size: float
    line_h: float
    lines: list[str]

    @property
    def char_w(self) -> float:
        return COURIER_ADVANCE * self.font_size

    @property
    def line_y(self) -> np.ndarray:
        return self.y0 + self.line_h * np.arange(len(self.lines))

    @property
    def px_per_deg(self) -> float:
        return self.char_w * LETTERS_PER_DEG


@dataclass(frozen=True)
class FixationTrial:
    """One reader's fixations over one passage (times in ms, positions in screen px)."""

    trial_id: str
    passage_id: str
    x: np.ndarray
    y: np.ndarray
    start_ms: np.ndarray
    end_ms: np.ndarray
    discarded: np.ndarray  # bool: belongs to no line (gold files only)

    def __len__(self) -> int:
        return int(self.x.size)


def load_passages(path: str | Path) -> dict[str, Passage]:
    doc = json.loads(Path(path).read_text(encoding="utf-8"))
    out = {}
    for pid, item in doc.items():
        block = item["__TextBlock__"]
        x0, y0 = (float(v) for v in block["position"])
        out[pid] = Passage(pid, x0, y0, float(block["font_size"]), float(block["line_height"]), list(block["text"]))
    return out


def load_fixation_trials(path: str | Path) -> dict[str, FixationTrial]:
    """Trials of a drift-format fixation file (``fixations_adult.json`` or ``gold_adult.json``)."""
    doc = json.loads(Path(path).read_text(encoding="utf-8"))
    out = {}
    for tid, trial in doc.items():
        seq = trial["fixations"]["__FixationSequence__"]
        out[tid] = FixationTrial(
            tid,
            str(trial["passage_id"]),
            np.array([f["x"] for f in seq], dtype=np.float64),
            np.array([f["y"] for f in seq], dtype=np.float64),
            np.array([f["start"] for f in seq], dtype=np.float64),
            np.array([f["end"] for f in seq], dtype=np.float64),
            np.array([bool(f.get("discarded", False)) for f in seq]),
        )
    return out


def gold_lines(gold: FixationTrial, passage: Passage) -> np.ndarray:
    """Gold line index per fixation (-1 for a discarded fixation)."""
    line = np.rint((gold.y - passage.y0) / passage.line_h).astype(np.int64)
    return np.where(gold.discarded, -1, line)


@dataclass(frozen=True)
class RawGaze:
    """Raw samples (NaN while the eye was lost) with the tracker's own events; times in ms."""

    t_ms: np.ndarray
    x: np.ndarray
    y: np.ndarray
    fixations: np.ndarray  # [n, 4]: start, end, x, y
    blinks: np.ndarray  # [n, 2]: start, end
    chars: list[tuple[str, float, float, float, float]]  # character, x0, y0, x1, y1
    px_per_deg: tuple[float, float]  # the tracker's resolution (x, y)


_REGION = re.compile(r"^MSG\s+\d+\s+REGION CHAR\s+\d+\s+\d+\s(.)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)")


def load_eyelink_asc(path: str | Path) -> RawGaze:
    """Samples, EFIX/EBLINK events, REGION CHAR boxes and the RES resolution of one ASC trial."""
    t, x, y, fix, blinks, chars = [], [], [], [], [], []
    res = (math.nan, math.nan)
    for line in Path(path).read_text(encoding="latin-1").splitlines():
        head = line[:1]
        if head.isdigit():
            parts = line.split()
            t.append(float(parts[0]))
            x.append(float(parts[1]) if parts[1] != "." else math.nan)
            y.append(float(parts[2]) if parts[2] != "." else math.nan)
        elif line.startswith("EFIX"):
            p = line.split()
            fix.append((float(p[2]), float(p[3]), float(p[5]), float(p[6])))
        elif line.startswith("EBLINK"):
            p = line.split()
            blinks.append((float(p[2]), float(p[3])))
        elif line.startswith("MSG") and "REGION CHAR" in line:
            m = _REGION.match(line)
            if m:
                chars.append((m.group(1), float(m.group(2)), float(m.group(3)), float(m.group(4)), float(m.group(5))))
        elif line.startswith("END") and "RES" in line:
            p = line.split()
            res = (float(p[-2]), float(p[-1]))
    if not t:
        raise ValueError(f"{path}: no samples (not an EyeLink ASC file?)")
    return RawGaze(np.array(t), np.array(x), np.array(y), np.array(fix).reshape(-1, 4), np.array(blinks).reshape(-1, 2),
                   chars, res)


@dataclass(frozen=True)
class NoiseModel:
    """Aria-like tracker error in degrees, as the synthesiser's tracker model draws it (midpoints):
    a constant bias, a slow error (low-passed over ~1 s) and per-sample noise; ~1.1 deg RMS per axis."""

    bias_deg: float = 0.9
    slow_deg: float = 0.5
    fast_deg: float = 0.35
    slow_tau_s: float = 1.0
    missing_p: float = 0.02  # rows the tracker drops
    jitter: float = 0.03  # row-time jitter, fraction of the period

    @property
    def rms_deg(self) -> float:
        return math.sqrt(self.bias_deg**2 + self.slow_deg**2 + self.fast_deg**2)


def aria_like_noise(t_s: np.ndarray, rng: np.random.Generator, model: NoiseModel = NoiseModel()) -> np.ndarray:
    """[len(t), 2] tracker error (deg) at times ``t_s``: bias + slow AR(1) + white noise."""
    t = np.asarray(t_s, dtype=np.float64)
    n = t.size
    bias = rng.normal(0.0, model.bias_deg, 2)
    slow = np.zeros((n, 2))
    if n:
        alpha = np.exp(-np.diff(t, prepend=t[0]) / model.slow_tau_s)
        steps = rng.normal(0.0, 1.0, (n, 2))
        slow[0] = steps[0]
        for i in range(1, n):  # one step per tracker row (tens per second), not per event
            slow[i] = alpha[i] * slow[i - 1] + math.sqrt(1.0 - alpha[i] ** 2) * steps[i]
    return bias[None, :] + model.slow_deg * slow + rng.normal(0.0, model.fast_deg, (n, 2))


def fixation_noise(start_ms: np.ndarray, end_ms: np.ndarray, rng: np.random.Generator, model: NoiseModel = NoiseModel(),
                   rate_hz: float = 60.0) -> np.ndarray:
    """[n, 2] error (deg) of fixation positions measured by an Aria-like tracker: bias and slow
    error at the fixation's midpoint, the per-row noise averaged over its rows at ``rate_hz``."""
    mid_s = (np.asarray(start_ms, dtype=np.float64) + np.asarray(end_ms, dtype=np.float64)) / 2000.0
    rows = np.maximum(1.0, (np.asarray(end_ms) - np.asarray(start_ms)) * rate_hz / 1000.0)
    slow_only = NoiseModel(model.bias_deg, model.slow_deg, 0.0, model.slow_tau_s)
    err = aria_like_noise(mid_s, rng, slow_only)
    return err + rng.normal(0.0, model.fast_deg, err.shape) / np.sqrt(rows)[:, None]


def resample_rows(raw: RawGaze, rate_hz: float, rng: np.random.Generator, model: NoiseModel = NoiseModel()
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a ``rate_hz`` tracker would report of ``raw``: row times (ms, with jitter and dropped
    rows) and the gaze in degrees with Aria-like error added (NaN where the eye was lost)."""
    period = 1000.0 / rate_hz
    t0, t1 = raw.t_ms[0], raw.t_ms[-1]
    n = int((t1 - t0) / period)
    t = t0 + np.arange(n) * period + rng.normal(0.0, model.jitter * period, n)
    t = np.sort(np.clip(t, t0, t1))
    keep = rng.random(n) >= model.missing_p
    t = t[keep]
    idx = np.clip(np.searchsorted(raw.t_ms, t), 0, raw.t_ms.size - 1)  # the sample the camera saw
    x = raw.x[idx] / raw.px_per_deg[0]
    y = raw.y[idx] / raw.px_per_deg[1]
    err = aria_like_noise((t - t0) / 1000.0, rng, model)
    return t, x + err[:, 0], y + err[:, 1]
