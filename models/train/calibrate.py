"""The ink temperature: how much the network's logits must be softened to be probabilities.

The on-change mode averages the network's ink probability over a view's frames
(``edge.view_fusion``), so the probability should mean what it says. The net was trained with
binary cross-entropy plus soft Dice, and Dice pushes logits apart (over-confidence); temperature
scaling (Guo et al., ICML 2017), ``sigmoid(logits / T)`` with the one ``T`` that minimises the
log-loss on held-out windows, fixes that without moving the ``logits > 0`` threshold.
``darkread train calibrate VAL_DIR`` measures it; the edge uses
the one a network carries in its metadata (``--store T``; ``darkread.edge.reconstruct.INK_TEMPERATURE``
when it has none). Numpy and onnxruntime only (``--store``: onnx).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.reconstruct import INK_TEMPERATURE_KEY, Reconstructor, probability_from_logits
from darkread.models.train.data import load_dataset

TEMPERATURES = (0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0)


def log_loss(logits: np.ndarray, targets: np.ndarray, temperature: float) -> float:
    """Mean binary cross-entropy of ``sigmoid(logits / temperature)`` against 0/1 ``targets``."""
    z = np.asarray(logits, np.float64) / temperature
    y = np.asarray(targets, np.float64)
    return float(np.mean(np.logaddexp(0.0, z) - y * z))


def reliability(probability: np.ndarray, targets: np.ndarray, bins: int = 10) -> list[tuple[float, float, int]]:
    """(bin's lower edge, share of ink, pixels) per probability bin: a calibrated net has share ~ bin."""
    p = np.asarray(probability).ravel()
    y = np.asarray(targets).ravel()
    index = np.minimum((p * bins).astype(np.int64), bins - 1)
    counts = np.bincount(index, minlength=bins)
    ink = np.bincount(index, weights=y, minlength=bins)
    return [(b / bins, float(ink[b] / counts[b]) if counts[b] else float("nan"), int(counts[b])) for b in range(bins)]


@dataclass
class Calibration:
    temperature: float
    windows: int
    losses: dict[float, float]  # temperature -> log-loss
    reliability: list[tuple[float, float, int]]  # at the fitted temperature

    def to_markdown(self) -> str:
        rows = ["| T | log-loss |", "|---:|---:|"]
        rows += [f"| {t:g}{' (best)' if t == self.temperature else ''} | {v:.4f} |" for t, v in self.losses.items()]
        rows += ["", f"reliability at T = {self.temperature:g} ({self.windows} windows):", "",
                 "| probability | share of ink | pixels |", "|---|---:|---:|"]
        rows += [f"| {lo:.1f}-{lo + 0.1:.1f} | {share:.3f} | {n} |" for lo, share, n in self.reliability]
        return "\n".join(rows)


def fit_temperature(logits: np.ndarray, targets: np.ndarray, temperatures: Sequence[float] = TEMPERATURES) -> Calibration:
    """The grid temperature with the lowest log-loss (the loss is smooth and has one minimum in T)."""
    losses = {float(t): log_loss(logits, targets, float(t)) for t in temperatures}
    best = min(losses, key=losses.__getitem__)

    table = reliability(probability_from_logits(logits, best), targets)
    return Calibration(best, int(np.asarray(logits).shape[0]), losses, table)


def calibrate(val_dir: str | Path, model: str | Path | None = None, limit: int | None = 500) -> Calibration:
    """Fit the temperature of ``model`` (default: the shipped one) on a shard directory's windows."""

    data = load_dataset(val_dir, limit=limit)
    rec = Reconstructor(model, threads=1, warmup=0)
    voxels = data.voxels[:limit] if limit else data.voxels
    logits = np.concatenate([rec.logits(voxels[i : i + 32].astype(np.float32)) for i in range(0, len(voxels), 32)])
    return fit_temperature(logits, data.targets[: len(logits)])


def stored_ink_temperature(path: str | Path) -> float | None:
    """The ink temperature a network file carries in its metadata, or None when it carries none."""
    import onnx


    for entry in onnx.load(str(path), load_external_data=False).metadata_props:
        if entry.key == INK_TEMPERATURE_KEY:
            return float(entry.value)
    return None


def store_ink_temperature(path: str | Path, temperature: float) -> Path:
    """Write ``temperature`` into the model's metadata (``edge.reconstruct.INK_TEMPERATURE_KEY``): the
    edge's ink probability is sigmoid(logits / T) with the T its network carries."""
    import onnx


    if not 0 < float(temperature) < float("inf"):
        raise ValueError(f"ink temperature must be a positive number, not {temperature}")
    model = onnx.load(str(path))
    kept = [p for p in model.metadata_props if p.key != INK_TEMPERATURE_KEY]
    del model.metadata_props[:]
    model.metadata_props.extend(kept)
    entry = model.metadata_props.add()
    entry.key, entry.value = INK_TEMPERATURE_KEY, repr(float(temperature))
    onnx.save(model, str(path))
    return Path(path)
