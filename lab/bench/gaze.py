"""Gaze events on a real reader: fixation-onset F1 of the online classifier at Aria's rates.

``../shared/data/reading_gaze/oz`` holds 1000 Hz EyeLink samples of one person reading a page with
EyeLink's own fixation events. Resampled to 10/30/60/90 Hz (row jitter, 2 % rows dropped) with
Aria-like tracker error (bias 0.9 deg, slow 0.5 deg over ~1 s, per-row 0.35 deg: ~1.1 deg RMS per
axis), the online classifier's fixation onsets are matched to EyeLink's within 50 ms
(``gaze_fixation_onset_f1_<rate>hz``, mean over seeds). The reference in the same run is the same
classifier on noise-free rows, the best a tracker of that rate allows.
"""

from __future__ import annotations

from darkread.lab.bench import BenchContext, Figure
from darkread.lab.gaze import human
from darkread.lab.gaze.scores import ARIA_RATES_HZ, oz_onset_scores


def run(ctx: BenchContext) -> list[Figure]:
    if ctx.shared_data is None or not (ctx.shared_data / "reading_gaze" / "oz").is_dir():
        ctx.notes.append("gaze: ../shared/data/reading_gaze/oz absent; fixation-onset F1 not measured")
        return []

    raw = human.load_eyelink_asc(ctx.shared_data / "reading_gaze" / "oz" / "OZ_1trial.txt")
    seeds = range(ctx.runs(10, 3))
    clean = human.NoiseModel(bias_deg=0.0, slow_deg=0.0, fast_deg=0.0)
    figures = []
    for rate in ARIA_RATES_HZ:
        noisy = oz_onset_scores(raw, rate, seeds)
        best = oz_onset_scores(raw, rate, range(1), noise=clean)
        figures.append(Figure(
            key=f"gaze_fixation_onset_f1_{rate:g}hz",
            value=round(noisy.f1, 3),
            label=f"fixation-onset F1 (50 ms), oz reader at {rate:g} Hz + Aria-like noise",
            reference=f"noise-free rows: {best.f1:.3f}; P {noisy.precision:.2f} R {noisy.recall:.2f}",
            goal=">= 0.9" if rate == 60.0 else "informational",
        ))
    return figures
