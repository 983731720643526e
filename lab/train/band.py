"""One network across the sensor's plausible band: the fitted network tuned on what the glasses cut while
someone reads under the grounded sensor model (the photoreceptor's K drawn over 40-400 Hz per chip-lux, the
noise process, both bias profiles, grounded head motion), with the standard regime rehearsed in every batch.

The fit from scratch (``models/train/pipeline.py``) learns from random page crops of the standard sensor
model; the dark reading windows of the grounded one differ in how slow pixels smear and how the noise
process fires. Crops of the grounded model did not teach that (two such tunes read its dark pages worse,
models/MODEL_CARD.md); reading windows, cut as the edge cuts them, did (docs/finetune.md, "One network across
the band"). ``tune_across_band`` makes the three window sets it needs (those absent) and tunes with the
recipe below (``darkread train band``); its network is `lab/networks/binary_unet_band.onnx`, not shipped yet.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from darkread.lab.train.rehearsal import describe, make_rehearsal
from darkread.models.synth.shards import build_dataset
from darkread.models.train.data import shard_paths
from darkread.models.train.finetune import TuneConfig, finetune


@dataclass(frozen=True)
class BandRecipe:
    """The tune across the band that made ``lab/networks/binary_unet_band.onnx`` (docs/finetune.md)."""

    grounded_sessions: int = 36  # rehearsal.GROUNDED_LUX_LEVELS x motions x both bias profiles, once
    session_s: float = 2.5  # each reading session's length; a window every 10 ms of it
    grounded_seed: int = 700
    standard_sessions: int = 18  # the standard regime rehearsed (rehearsal.LUX_LEVELS x motions)
    standard_seed: int = 601
    crops: int = 750  # random page crops of the standard regime (`synth dataset`), the first 96 held out
    crops_seed: int = 17
    synthetic_share: float = 0.5  # of every batch: the standard regime's windows
    anchor: float = 3.0  # on those, the starting network's own answer against the truth (learning without forgetting)
    train_only: tuple[str, ...] = ("stem", "down1", "down2")  # where a sensor's difference enters
    lr: float = 2e-4
    steps: int = 3000
    minutes: float = 60.0  # a cap; the steps end it (about 5 min on one quiet core)
    seed: int = 0


BAND_RECIPE = BandRecipe()


def band_sets(work: str | Path) -> dict[str, Path]:
    """Where the recipe's three window sets live under ``work``."""
    root = Path(work)
    return {"grounded": root / "rehearsal_grounded", "standard": root / "rehearsal_standard", "crops": root / "crops"}


def make_band_sets(work: str | Path, recipe: BandRecipe = BAND_RECIPE, jobs: int = 1, progress: bool = True) -> dict[str, str]:
    """The grounded and standard reading windows and the crops (each resumes; a finished set is kept);
    what each reading set holds, on one line."""
    sets = band_sets(work)
    grounded = make_rehearsal(sets["grounded"], count=recipe.grounded_sessions, seed=recipe.grounded_seed,
                              seconds=recipe.session_s, jobs=jobs, progress=progress, regime="grounded")
    standard = make_rehearsal(sets["standard"], count=recipe.standard_sessions, seed=recipe.standard_seed,
                              seconds=recipe.session_s, jobs=jobs, progress=progress, regime="standard")
    try:
        shard_paths(sets["crops"])
    except FileNotFoundError:
        build_dataset(sets["crops"], recipe.crops, workers=jobs, seed=recipe.crops_seed, split="train")
    return {"grounded": describe(grounded), "standard": describe(standard)}


def tune_across_band(base: str | Path, work: str | Path, export_to: str | Path, *, recipe: BandRecipe = BAND_RECIPE,
                     jobs: int = 1, progress: bool = True) -> dict[str, Any]:
    """``base`` (ONNX) tuned across the band with ``recipe``; the tuned network written to ``export_to``."""
    started = time.monotonic()
    held = make_band_sets(work, recipe, jobs, progress)
    made = time.monotonic() - started
    sets = band_sets(work)
    cfg = TuneConfig(lr=recipe.lr, steps=recipe.steps, minutes=recipe.minutes, synthetic_share=recipe.synthetic_share,
                     seed=recipe.seed, anchor_weight=recipe.anchor, train_only=recipe.train_only)
    summary = finetune([sets["grounded"]], base, Path(work) / "tune", export_to, cfg=cfg, synthetic=None,
                       synthetic_dirs=[sets["crops"], sets["standard"]], progress=progress)
    info = {"recipe": asdict(recipe), "base": str(base), "exported": str(export_to), "sets": held, "sets_s": round(made, 1),
            "tune": {k: summary[k] for k in ("annotated_windows", "synthetic_windows", "steps", "seconds",
                                              "monitor_f1_before", "monitor_f1_after")}}
    (Path(work) / "band.json").write_text(json.dumps(info, indent=1, default=float) + "\n", encoding="utf-8")
    return info
