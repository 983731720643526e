"""Scores of darkread's gaze logic on real readers: fixation onsets (oz) and line assignment (drift).

Shared by the tests (``-m shared``), ``make bench`` and docs/gaze.md, so each figure is computed
one way.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.gaze_events import GazeEventConfig, classify_gaze, fixations
from darkread.lab.gaze import human
from darkread.lab.gaze.lines import DEFAULT_METHOD, EYEKIT_METHODS, STITCHER, fixation_lines

ONSET_TOLERANCE_MS = 50.0
ARIA_RATES_HZ: tuple[float, ...] = (10.0, 30.0, 60.0, 90.0)


@dataclass(frozen=True)
class OnsetScore:
    f1: float
    precision: float
    recall: float
    found: int
    true: int


def onset_f1(found_ms: np.ndarray, true_ms: np.ndarray, tol_ms: float = ONSET_TOLERANCE_MS) -> OnsetScore:
    """One-to-one matching of onsets within ``tol_ms`` (each true onset takes the nearest free one)."""
    found = np.sort(np.asarray(found_ms, dtype=np.float64))
    used = np.zeros(found.size, dtype=bool)
    hits = 0
    for t in np.asarray(true_ms, dtype=np.float64):
        d = np.abs(found - t)
        d[used] = np.inf
        if d.size and d.min() <= tol_ms:
            used[int(d.argmin())] = True
            hits += 1
    p = hits / max(found.size, 1)
    r = hits / max(len(true_ms), 1)
    return OnsetScore(2 * p * r / max(p + r, 1e-12), p, r, int(found.size), int(len(true_ms)))


def oz_onset_scores(raw: human.RawGaze, rate_hz: float, seeds: range = range(5),
                    noise: human.NoiseModel = human.NoiseModel(), cfg: GazeEventConfig = GazeEventConfig()) -> OnsetScore:
    """Fixation-onset F1 of the online classifier against EyeLink's own fixations, the 1000 Hz
    samples resampled to ``rate_hz`` with Aria-like noise; mean over ``seeds``."""
    scores = []
    for seed in seeds:
        t_ms, x, y = human.resample_rows(raw, rate_hz, np.random.default_rng([int(rate_hz), seed]), noise)
        events = classify_gaze(np.rint(t_ms * 1000).astype(np.int64), x, y, cfg.for_rate(rate_hz))
        scores.append(onset_f1(fixations(events)["t0_us"] / 1000.0, raw.fixations[:, 0]))
    mean = {k: float(np.mean([getattr(s, k) for s in scores])) for k in ("f1", "precision", "recall")}
    return OnsetScore(mean["f1"], mean["precision"], mean["recall"], int(np.mean([s.found for s in scores])), scores[0].true)


def method_name(method: str | tuple[str, ...]) -> str:
    return method if isinstance(method, str) else "vote(" + ", ".join(method) + ")"


def line_accuracy(drift_dir: str | Path, methods, noise: human.NoiseModel | None = None, seed: int = 0) -> dict[str, float]:
    """Share of the non-discarded fixations of the drift trials put on their gold line, per method;
    with ``noise``, every fixation moved by an Aria-like tracker error (deg -> px by the passage:
    ``LETTERS_PER_DEG`` characters of its font per degree)."""
    drift_dir = Path(drift_dir)
    passages = human.load_passages(drift_dir / "passages.json")
    trials = human.load_fixation_trials(drift_dir / "fixations_adult.json")
    golds = human.load_fixation_trials(drift_dir / "gold_adult.json")
    hits = {method_name(m): 0 for m in methods}
    total = 0
    rng = np.random.default_rng(seed)
    for tid, trial in trials.items():
        passage = passages[trial.passage_id]
        gold = human.gold_lines(golds[tid], passage)
        x, y = trial.x, trial.y
        if noise is not None:
            err = human.fixation_noise(trial.start_ms, trial.end_ms, rng, noise) * passage.px_per_deg
            x, y = x + err[:, 0], y + err[:, 1]
        keep = gold >= 0
        total += int(keep.sum())
        for m in methods:
            got = fixation_lines(x, y, trial.start_ms, trial.end_ms, passage, m)
            hits[method_name(m)] += int((got[keep] == gold[keep]).sum())
    return {k: v / max(total, 1) for k, v in hits.items()}


ALL_LINE_METHODS: tuple = (STITCHER, DEFAULT_METHOD, *EYEKIT_METHODS)
