"""Held-out evaluation: the shipped ONNX networks (fp32, int8) next to the naive baseline,
broken down by illuminance and motion level, plus the sample figure for the model card.

Runs on onnxruntime (what ships), not torch, so the numbers are those of the product.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from darkread.edge.reconstruct import Reconstructor
from darkread.models.train.baseline import BaselineParams
from darkread.models.train.baseline import predict as baseline_predict
from darkread.models.train.data import Shard, iterate_batches, load_dataset, shard_paths
from darkread.models.train.ink_scores import ink_counts, scores_from_counts

log = logging.getLogger(__name__)

LUX_LEVELS: tuple[float, ...] = (1000, 100, 30, 10, 5)


def predict_onnx(model_path: str | Path, voxels: np.ndarray, batch_size: int = 32, progress: bool = False) -> np.ndarray:
    """uint8 ink masks of ``voxels`` through the edge Reconstructor."""
    from tqdm import tqdm


    rec = Reconstructor(model_path, threads=1, warmup=1)
    out = np.zeros((len(voxels), *voxels.shape[-2:]), np.uint8)
    for b in tqdm(range(0, len(voxels), batch_size), desc=Path(model_path).name, disable=not progress, leave=False):
        out[b : b + batch_size] = rec(voxels[b : b + batch_size].astype(np.float32))
    return out


def motion_levels(motion: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Group labels per sample: the values themselves when categorical, else terciles."""
    values = np.asarray(motion)
    if values.dtype.kind in "USO" or len(np.unique(values)) <= 5:
        labels = [str(v) for v in values]
        return np.array(labels), sorted(set(labels), key=lambda s: (len(s), s))
    lo, hi = np.quantile(values.astype(float), [1 / 3, 2 / 3])
    names = [f"low (< {lo:.3g})", f"mid ({lo:.3g} to {hi:.3g})", f"high (> {hi:.3g})"]
    index = np.digitize(values.astype(float), [lo, hi])
    return np.array([names[i] for i in index]), names


def grouped_scores(preds: dict[str, np.ndarray], targets: np.ndarray, groups: np.ndarray, order: Iterable[str]) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    for name in order:
        mask = groups == name
        if not mask.any():
            continue
        row: dict[str, object] = {"group": name, "n": int(mask.sum())}
        for method, pred in preds.items():
            s = scores_from_counts(*ink_counts(pred[mask], targets[mask]))
            row[f"{method}_f1"] = s["f1"]
            row[f"{method}_iou"] = s["iou"]
        rows.append(row)
    return rows


def lux_groups(lux: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Each sample's nearest level of ``LUX_LEVELS`` on a log scale, labelled with the bin's range."""
    levels = np.array(sorted(LUX_LEVELS))
    edges = np.sqrt(levels[:-1] * levels[1:])  # geometric midpoints
    names = []
    for i, level in enumerate(levels):
        lo = f"{edges[i - 1]:.0f}" if i > 0 else None
        hi = f"{edges[i]:.0f}" if i < len(edges) else None
        span = f"{lo}-{hi}" if lo and hi else (f"< {hi}" if hi else f">= {lo}")
        names.append(f"{level:g} ({span})")
    index = np.searchsorted(edges, np.asarray(lux, float), side="right")
    labels = np.array([names[i] for i in index])
    order = [names[i] for i in np.argsort([-lv for lv in levels])]
    return labels, order


def training_sample(train_dir: str | Path, n: int, seed: int = 0) -> Shard:
    """Up to ``n`` training-split samples (for tuning the baseline and int8 calibration)."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    total = 0
    for x, y in iterate_batches(shard_paths(train_dir), 64, rng, augmentation=False, shards_in_memory=1):
        xs.append(x.astype(np.float16))
        ys.append(y)
        total += len(x)
        if total >= n:
            break
    return Shard(np.concatenate(xs)[:n], np.concatenate(ys)[:n], {})


def evaluate(
    models: dict[str, Path],
    val_dir: str | Path,
    baseline: BaselineParams,
    *,
    limit: int | None = None,
    progress: bool = True,
) -> dict[str, object]:
    """Scores of each model in ``models`` (name -> onnx path) and of the baseline on ``val_dir``."""
    data = load_dataset(val_dir, limit=limit)
    targets = data.targets.astype(bool)
    preds = {name: predict_onnx(path, data.voxels, progress=progress).astype(bool) for name, path in models.items()}
    preds["baseline"] = baseline_predict(data.voxels, baseline).astype(bool)
    overall = {"group": "all", "n": len(data)}
    for method, pred in preds.items():
        s = scores_from_counts(*ink_counts(pred, targets))
        overall[f"{method}_f1"] = s["f1"]
        overall[f"{method}_iou"] = s["iou"]
    report: dict[str, object] = {"samples": len(data), "overall": overall, "baseline_params": baseline.to_dict()}
    if "lux" in data.meta:
        groups, order = lux_groups(data.meta["lux"])
        report["by_lux"] = grouped_scores(preds, targets, groups, order)
    if "motion" in data.meta:
        groups, order = motion_levels(data.meta["motion"])
        report["by_motion"] = grouped_scores(preds, targets, groups, order)
    if "font" in data.meta:
        fonts = np.array([str(f) for f in data.meta["font"]])
        report["by_font"] = grouped_scores(preds, targets, fonts, sorted(set(fonts)))
    manifest = Path(val_dir) / "dataset.json"
    if manifest.is_file():
        report["dataset"] = json.loads(manifest.read_text())
    return report


def sample_figure(
    model_path: Path, val_dir: str | Path, out_path: str | Path, baseline: BaselineParams | None = None,
    lux_values: tuple[float, ...] = (1000, 5), per_lux: int = 3, limit: int | None = 2000, seed: int = 0,
) -> Path:
    """Events | prediction | (baseline) | target for a few held-out windows at each lux level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = load_dataset(val_dir, limit=limit)
    rng = np.random.default_rng(seed)
    chosen: list[tuple[float, int]] = []
    lux = np.asarray(data.meta.get("lux", np.full(len(data), 1000.0)), float)
    for level in lux_values:
        candidates = np.flatnonzero(np.isclose(lux, level, rtol=0.2) & (data.targets.reshape(len(data), -1).mean(1) > 0.03))
        if len(candidates) == 0:
            candidates = np.flatnonzero(np.isclose(lux, level, rtol=0.2))
        chosen += [(level, int(i)) for i in rng.choice(candidates, size=min(per_lux, len(candidates)), replace=False)]
    voxels = data.voxels[[i for _, i in chosen]].astype(np.float32)
    preds = predict_onnx(model_path, voxels)
    columns = ["events (ON red, OFF blue)", "network", *(["naive baseline"] if baseline else []), "target"]
    fig, axes = plt.subplots(len(chosen), len(columns), figsize=(3.2 * len(columns), 1.75 * len(chosen)), squeeze=False)
    for row, ((level, index), voxel, pred) in enumerate(zip(chosen, voxels, preds)):
        signed = voxel.sum(0)
        scale = float(np.abs(signed).max()) or 1.0
        panels = [("events", signed), ("net", pred)]
        if baseline:
            panels.append(("baseline", baseline_predict(voxel, baseline)))
        panels.append(("target", data.targets[index]))
        for col, (kind, image) in enumerate(panels):
            ax = axes[row, col]
            if kind == "events":
                ax.imshow(signed, cmap="bwr", vmin=-scale, vmax=scale, interpolation="nearest")
            else:
                ax.imshow(1 - image, cmap="gray", vmin=0, vmax=1, interpolation="nearest")  # black ink on white
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(columns[col], fontsize=9)
            if col == 0:
                font = str(data.meta["font"][index]) if "font" in data.meta else ""
                ax.set_ylabel(f"{level:g} lux\n{font[:18]}", fontsize=8)
    fig.tight_layout()
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return out
