"""The steps that turn a training run into the shipped model: export, int8, evaluate, card.

``reproduce`` chains them after dataset generation and fitting (``darkread train all``).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from darkread.models import FIGURE_PATH, MODELS_DIR
from darkread.models.synth.shards import LUX_RANGE, build_dataset
from darkread.models.train.baseline import tune
from darkread.models.train.card import write_card
from darkread.models.train.data import shard_paths
from darkread.models.train.evaluate import evaluate, sample_figure, training_sample
from darkread.models.train.export import export_onnx, quantize_int8
from darkread.models.train.fit import BEST_CHECKPOINT, FitConfig, fit, load_model
from darkread.models.train.latency import onnx_latency_ms, reference_latency_ms
from darkread.models.train.net import BinaryUNet, NetConfig, count_parameters

log = logging.getLogger(__name__)

FP32_NAME = "binary_unet.onnx"
INT8_NAME = "binary_unet_int8.onnx"
CARD_NAME = "MODEL_CARD.md"
DEFAULT_RUN_DIR = Path("runs/binary_unet")


def export_models(checkpoint: str | Path, train_dir: str | Path, out_dir: str | Path = MODELS_DIR, calibration_windows: int = 256) -> dict[str, Any]:
    """fp32 ONNX from ``checkpoint`` and its int8 twin calibrated on training windows."""

    out = Path(out_dir)
    fp32 = export_onnx(load_model(checkpoint), out / FP32_NAME)
    calib = training_sample(train_dir, calibration_windows, seed=1)
    int8 = quantize_int8(fp32, out / INT8_NAME, calib.voxels.astype(np.float32))
    info = {"fp32": str(fp32), "int8": str(int8), "checkpoint": str(checkpoint), "calibration_windows": len(calib)}
    (Path(checkpoint).parent / "export.json").write_text(json.dumps(info, indent=1))
    return info


def measure_latency(models_dir: str | Path = MODELS_DIR, runs: int = 60) -> dict[str, Any]:
    import onnxruntime


    ref_ms, ref = reference_latency_ms(runs)
    out = Path(models_dir)
    return {
        "fp32_ms": onnx_latency_ms(out / FP32_NAME, runs),
        "int8_ms": onnx_latency_ms(out / INT8_NAME, runs),
        "reference_ms": ref_ms,
        "reference": ref.split(":")[0],
        "ort_version": onnxruntime.__version__,
    }


def evaluate_models(
    train_dir: str | Path, val_dir: str | Path, models_dir: str | Path = MODELS_DIR, *,
    baseline_windows: int = 600, limit: int | None = None, figure: str | Path | None = FIGURE_PATH,
) -> dict[str, Any]:

    tuning = training_sample(train_dir, baseline_windows, seed=2)
    params, train_f1 = tune(tuning.voxels, tuning.targets)
    log.info("naive baseline tuned on %d training windows: %s (train F1 %.3f)", len(tuning), params, train_f1)
    out = Path(models_dir)
    report = evaluate({"fp32": out / FP32_NAME, "int8": out / INT8_NAME}, val_dir, params, limit=limit)
    report["baseline_train_f1"] = train_f1
    if figure is not None:
        sample_figure(out / FP32_NAME, val_dir, figure, baseline=params)
    return report


def _manifest(root: str | Path) -> dict[str, Any] | None:
    path = Path(root) / "dataset.json"
    return json.loads(path.read_text()) if path.is_file() else None


def _families(fonts: Any) -> list[str]:
    if isinstance(fonts, dict):
        return list(fonts.get("families_in_this_set", []))
    return list(fonts or [])


def write_model_card(info: dict[str, Any], models_dir: str | Path = MODELS_DIR) -> Path:

    return write_card(info, Path(models_dir) / CARD_NAME)


def finish(
    run_dir: str | Path, train_dir: str | Path, val_dir: str | Path, *, models_dir: str | Path = MODELS_DIR,
    timings: dict[str, float] | None = None, eval_limit: int | None = None, figure: str | Path | None = FIGURE_PATH,
) -> dict[str, Any]:
    """export -> int8 -> evaluate -> latency -> card, from the best checkpoint of ``run_dir``."""
    timings = dict(timings or {})
    started = time.monotonic()
    export_models(Path(run_dir) / BEST_CHECKPOINT, train_dir, models_dir)
    timings["export + int8"] = time.monotonic() - started
    return evaluate_and_card(run_dir, train_dir, val_dir, models_dir=models_dir, timings=timings, eval_limit=eval_limit, figure=figure)


def evaluate_and_card(
    run_dir: str | Path, train_dir: str | Path, val_dir: str | Path, *, models_dir: str | Path = MODELS_DIR,
    timings: dict[str, float] | None = None, eval_limit: int | None = None, figure: str | Path | None = FIGURE_PATH,
) -> dict[str, Any]:
    """Evaluate the exported models, measure latency, draw the figure, write the card and evaluation.json."""
    timings = dict(timings or {})
    run = Path(run_dir)
    out = Path(models_dir)
    exported = {
        "size_fp32_kb": (out / FP32_NAME).stat().st_size / 1024,
        "size_int8_kb": (out / INT8_NAME).stat().st_size / 1024,
    }
    export_info = run / "export.json"
    if export_info.is_file():
        exported["calibration_windows"] = json.loads(export_info.read_text()).get("calibration_windows", "?")
    started = time.monotonic()
    report = evaluate_models(train_dir, val_dir, models_dir, limit=eval_limit, figure=figure)
    timings["evaluate"] = time.monotonic() - started
    latency = measure_latency(models_dir)
    history = json.loads((run / "history.json").read_text())
    timings.setdefault("fit", float(history["elapsed_s"]))
    fit_info = {**history["fit_config"], "steps": history["step"], "epochs": history["epoch"],
                "elapsed_s": history["elapsed_s"], "best_f1": history["best_f1"]}

    fit_info["parameters"] = count_parameters(BinaryUNet(NetConfig.from_dict(fit_info["net"])))
    train_manifest = _manifest(train_dir)
    info = {
        **exported, "report": report, "fit": fit_info, "latency": latency, "timings_s": timings,
        "train_manifest": train_manifest, "train_dir": str(train_dir), "val_dir": str(val_dir),
        "train_fonts": _families((train_manifest or {}).get("fonts")),
    }
    (run / "evaluation.json").write_text(json.dumps(info, indent=1, default=str))
    write_model_card(info, models_dir)
    return info


@dataclass(frozen=True)
class SetRecipe:
    """One synthetic set of the shipped network's recipe: ``darkread synth dataset`` with these options."""

    folder: str  # beside the training set's folder (the first set is the training set's folder itself)
    samples: int
    seed: int
    split: str = "train"
    lux: tuple[float, float] | None = None  # None: the training range, 4-1200 lux
    more_fonts: bool = False

    def scaled(self, samples: int) -> SetRecipe:
        return replace(self, samples=max(1, samples))


# the shipped network's training sets: the whole light range, then two dim sets of the same scenes,
# one in the three training families and one in five (`synth dataset --more-fonts`)
TRAINING_RECIPE: tuple[SetRecipe, ...] = (
    SetRecipe("train", 30000, 61),
    SetRecipe("dim", 5000, 71, lux=(4.0, 40.0)),
    SetRecipe("dim_more_fonts", 5000, 71, lux=(4.0, 40.0), more_fonts=True),
)
VALIDATION_RECIPE = SetRecipe("val", 2000, 2, split="val")


def training_sets(train_dir: str | Path, train_samples: int = TRAINING_RECIPE[0].samples) -> list[tuple[Path, SetRecipe]]:
    """Where each set of the recipe lives and how many windows it has: the first in ``train_dir``, the
    others beside it; ``train_samples`` scales them all alike (a smaller reproduction keeps the mix)."""
    first = Path(train_dir)
    scale = train_samples / TRAINING_RECIPE[0].samples
    return [(first if i == 0 else first.parent / r.folder, r.scaled(round(r.samples * scale)))
            for i, r in enumerate(TRAINING_RECIPE)]


def reproduce(
    train_dir: str | Path, val_dir: str | Path, run_dir: str | Path = DEFAULT_RUN_DIR, *,
    config: FitConfig | None = None, train_samples: int = TRAINING_RECIPE[0].samples,
    val_samples: int = VALIDATION_RECIPE.samples, workers: int = 2,
    models_dir: str | Path = MODELS_DIR, figure: str | Path | None = FIGURE_PATH,
) -> dict[str, Any]:
    """The recipe's synthetic sets (those absent) -> fit on their mix -> export -> int8 -> evaluate -> model card."""

    timings: dict[str, float] = {}
    sets = training_sets(train_dir, train_samples)
    for root, recipe in [*sets, (Path(val_dir), VALIDATION_RECIPE.scaled(val_samples))]:
        try:
            shard_paths(root)
            continue
        except FileNotFoundError:
            pass
        started = time.monotonic()
        generate_dataset(recipe, root, workers)
        timings[f"synthesise {root.name} ({recipe.samples} windows)"] = time.monotonic() - started
    started = time.monotonic()
    config = config or FitConfig()
    fit([root for root, _ in sets], run_dir, config)
    timings["fit"] = time.monotonic() - started
    log.info("fit config: %s", asdict(config))
    return finish(run_dir, train_dir, val_dir, models_dir=models_dir, timings=timings, figure=figure)


def generate_dataset(recipe: SetRecipe, root: str | Path, workers: int) -> None:
    """Make one set of the recipe as ``darkread synth dataset`` does."""

    log.info("generating %s: %s, %d workers -> %s", recipe.folder, recipe, workers, root)
    build_dataset(root, recipe.samples, workers=workers, seed=recipe.seed, split=recipe.split,
                  lux_range=recipe.lux or LUX_RANGE, more_fonts=recipe.more_fonts)
