"""Train the binary U-Net on synthetic shards: time-budgeted, checkpointed, resumable.

The learning rate follows a warm-up + cosine schedule over the *fraction of the budget used*
(the larger of wall time / time budget and epochs done / max epochs), so a run that is stopped
and resumed, or that runs on a slower machine, still ends with a decayed learning rate.
"""

from __future__ import annotations

import json
import logging
import math
import pickle
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TypedDict

import numpy as np
import torch
import torch.nn.functional as F

from darkread.models.train.data import (
    Shard,
    iterate_batches,
    load_shard,
    random_crop,
    shard_paths,
    split_mask,
)
from darkread.models.train.ink_scores import ink_scores
from darkread.models.train.net import BinaryUNet, NetConfig, count_parameters
from darkread.models.train.onnx_weights import model_from_onnx

log = logging.getLogger(__name__)

LAST_CHECKPOINT = "last.pt"
BEST_CHECKPOINT = "best.pt"


class FitState(TypedDict):
    """Where a run is: kept in every checkpoint, so a resumed run goes on from it."""

    step: int
    epoch: int
    elapsed_s: float
    best_f1: float
    history: list[dict[str, float]]


@dataclass
class FitConfig:
    """Everything that decides a training run (stored in every checkpoint)."""

    batch_size: int = 32
    lr: float = 3e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 200
    time_budget_s: float = 45 * 60
    max_epochs: int = 30
    threads: int = 2
    dice_weight: float = 0.5
    validation_samples: int = 512
    checkpoint_every_s: float = 120.0
    seed: int = 0
    augmentation: bool = True
    crop: tuple[int, int] | None = (64, 128)  # train on random crops (validation uses whole windows)
    freeze_batchnorm: bool = False  # keep BatchNorms in eval mode (weights from an ONNX file: folded, identity BNs)
    # distillation: a network (ONNX or checkpoint) whose ink probability the fit also learns to give,
    # with this share of the loss (the rest: the synthetic ground truth). A cheaper network that reads
    # like the one the edge's settings were tuned on, not only one with a good pixel score
    teacher: str | None = None
    teacher_weight: float = 0.8
    net: dict[str, object] = field(default_factory=lambda: NetConfig().to_dict())


def bce_dice_loss(logits: torch.Tensor, targets: torch.Tensor, dice_weight: float = 0.5,
                  valid: torch.Tensor | None = None) -> torch.Tensor:
    """BCE for per-pixel calibration plus soft Dice, which keeps thin, rare strokes from being ignored.

    ``valid`` (same shape, 1 = counts): pixels outside it add nothing to either term, nor to the
    gradient (an annotated window's markers); None = every pixel counts (the same loss as before).
    """
    if valid is None:
        bce = F.binary_cross_entropy_with_logits(logits, targets)
    else:
        bce = F.binary_cross_entropy_with_logits(logits, targets, weight=valid, reduction="sum") / valid.sum().clamp(min=1.0)
    if dice_weight <= 0:
        return bce
    prob = torch.sigmoid(logits) if valid is None else torch.sigmoid(logits) * valid
    targets = targets if valid is None else targets * valid
    dims = tuple(range(1, prob.ndim))
    inter = (prob * targets).sum(dims)
    dice = 1 - (2 * inter + 1) / (prob.sum(dims) + targets.sum(dims) + 1)
    return bce + dice_weight * dice.mean()


def schedule(progress: float, step: int, config: FitConfig) -> float:
    warm = min(1.0, (step + 1) / max(1, config.warmup_steps))
    cosine = 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))
    return config.lr * warm * (0.02 + 0.98 * cosine)


def validation_set(paths: list[Path], limit: int) -> Shard:
    """Held-out samples (split by seed) from the first shards, enough for ``limit`` samples."""
    parts: list[Shard] = []
    total = 0
    for path in paths:
        shard = load_shard(path)
        part = shard.select(np.flatnonzero(split_mask(shard, validation=True)))
        parts.append(part)
        total += len(part)
        if total >= limit:
            break
    voxels = np.concatenate([p.voxels for p in parts])[:limit]
    targets = np.concatenate([p.targets for p in parts])[:limit]
    return Shard(voxels, targets, {})


@torch.no_grad()
def evaluate_model(model: BinaryUNet, voxels: np.ndarray, targets: np.ndarray, batch_size: int = 64,
                   ignore: np.ndarray | None = None) -> dict[str, float]:
    """BCE and pooled ink F1 / IoU; pixels where ``ignore`` is set count in neither."""
    model.eval()
    losses, preds = [], []
    for b in range(0, len(voxels), batch_size):
        x = torch.from_numpy(voxels[b : b + batch_size].astype(np.float32))
        y = torch.from_numpy(targets[b : b + batch_size].astype(np.float32))[:, None]
        logits = model(x)
        w = None if ignore is None else torch.from_numpy((ignore[b : b + batch_size] == 0).astype(np.float32))[:, None]
        losses.append(float(bce_dice_loss(logits, y, 0.0, w)) * len(x))
        preds.append((logits[:, 0] > 0).numpy())
    pred = np.concatenate(preds) if preds else np.zeros((0, *targets.shape[1:]), bool)
    truth = targets.astype(bool)
    if ignore is not None:
        valid = ignore == 0
        pred, truth = pred[valid], truth[valid]
    scores = ink_scores(pred, truth)
    return {"bce": sum(losses) / max(1, len(voxels)), "f1": float(scores["f1"]), "iou": float(scores["iou"])}


def frozen(model: torch.nn.Module) -> torch.nn.Module:
    """``model`` in eval mode with no parameter learning: a teacher or an anchor whose answers are
    targets, never trained."""
    for parameter in model.parameters():
        parameter.requires_grad_(False)
    return model.eval()


def training_mode(model: torch.nn.Module, *, freeze_batchnorm: bool) -> None:
    """``model.train()``, the BatchNorms left in eval mode when frozen: an exported network's
    BatchNorms are folded into its convolutions, so batch statistics would undo what it learned."""
    model.train()
    if freeze_batchnorm:
        for module in model.modules():
            if isinstance(module, torch.nn.BatchNorm2d):
                module.eval()


def save_checkpoint(path: Path, model: BinaryUNet, optimizer: torch.optim.Optimizer, state: dict[str, object]) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(), **state}, tmp)
    tmp.replace(path)


def load_model(checkpoint: str | Path) -> BinaryUNet:
    """The network stored in a checkpoint, in eval mode (ValueError naming the file when it is not one)."""

    try:
        data = torch.load(checkpoint, map_location="cpu", weights_only=False)
        net = data["fit_config"]["net"]
    except (pickle.UnpicklingError, RuntimeError, EOFError, KeyError, TypeError) as exc:
        raise ValueError(f"{checkpoint}: not a training checkpoint ({type(exc).__name__}); give a .pt that "
                         "`darkread train fit` wrote, or an exported .onnx") from None
    config = NetConfig.from_dict(net)
    model = BinaryUNet(config)
    model.load_state_dict(data["model"])
    return model.eval()


def is_exported_network(path: str | Path) -> bool:
    """An ONNX file (BatchNorms folded into its convolutions, so a fit from it keeps them frozen), not a checkpoint."""
    return str(path).endswith(".onnx")


def load_initial_weights(path: str | Path, config: NetConfig | None, option: str = "--init") -> BinaryUNet:
    """Starting weights for a fit: a checkpoint (.pt) or an exported network (.onnx, e.g. the shipped one;
    ``config`` None: as it is, else the layers it shares with a network of ``config``); ``option``
    names where the path came from in the error for a missing file."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{option} {path}: no such file")
    if is_exported_network(path):
        return model_from_onnx(path, config)
    return load_model(path)


def fit(
    train_dir: str | Path | Sequence[str | Path],
    out_dir: str | Path,
    config: FitConfig | None = None,
    *,
    resume: bool = True,
    progress: bool = True,
    on_step: Callable[[int, float], None] | None = None,
    init_checkpoint: str | Path | None = None,
) -> dict[str, object]:
    """Train until the time budget or ``max_epochs`` is used; returns the final summary.

    An epoch is one pass over the shards present when it starts, so training can begin while
    the dataset is still being generated.

    ``out_dir`` receives ``last.pt`` (resumable), ``best.pt`` (best held-out F1) and ``history.json``.
    ``init_checkpoint`` starts from other weights (fine-tuning) instead of a fresh network.
    """
    from tqdm import tqdm

    config = config or FitConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    paths = shard_paths(train_dir)

    model = BinaryUNet(NetConfig.from_dict(config.net))
    if init_checkpoint is not None:
        model.load_state_dict(load_initial_weights(init_checkpoint, NetConfig.from_dict(config.net)).state_dict())
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    state: FitState = {"step": 0, "epoch": 0, "elapsed_s": 0.0, "best_f1": -1.0, "history": []}
    last = out / LAST_CHECKPOINT
    if resume and last.exists():
        data = torch.load(last, map_location="cpu", weights_only=False)
        model.load_state_dict(data["model"])
        optimizer.load_state_dict(data["optimizer"])
        state = FitState(step=data["step"], epoch=data["epoch"], elapsed_s=data["elapsed_s"], best_f1=data["best_f1"],
                         history=data["history"])
        rng = np.random.default_rng([config.seed, int(state["step"])])
        if data.get("fit_config", {}).get("freeze_batchnorm") and not config.freeze_batchnorm:
            config = replace(config, freeze_batchnorm=True)  # a run that began from an exported network stays frozen
        log.info("resumed from %s at step %s, %.0f s used", last, state["step"], state["elapsed_s"])
    log.info("network: %d parameters, %s", count_parameters(model), config.net)
    teacher = None
    if config.teacher is not None:
        teacher = frozen(load_initial_weights(config.teacher, None, option="--teacher"))
        log.info("distilling %s (%.0f %% of the loss)", config.teacher, 100 * config.teacher_weight)
    held_out = validation_set(paths, config.validation_samples)
    log.info("held-out validation samples: %d", len(held_out))

    def checkpoint(extra_best: bool = False) -> None:
        payload = {**state, "fit_config": asdict(config)}
        save_checkpoint(last, model, optimizer, payload)
        if extra_best:
            save_checkpoint(out / BEST_CHECKPOINT, model, optimizer, payload)
        (out / "history.json").write_text(json.dumps({**payload}, indent=1, default=float))

    def progress_fraction(epoch_done: float) -> float:
        return max(float(state["elapsed_s"]) / config.time_budget_s, epoch_done / config.max_epochs)

    def validate() -> None:
        scores = evaluate_model(model, held_out.voxels, held_out.targets)
        scores.update(step=int(state["step"]), epoch=float(state["epoch"]), elapsed_s=float(state["elapsed_s"]))
        state["history"].append(scores)
        better = scores["f1"] > float(state["best_f1"])
        if better:
            state["best_f1"] = scores["f1"]
        log.info("validation: %s", {k: round(v, 4) for k, v in scores.items()})
        checkpoint(extra_best=better)

    done = False
    while not done and int(state["epoch"]) < config.max_epochs:
        epoch = int(state["epoch"])
        training_mode(model, freeze_batchnorm=config.freeze_batchnorm)
        started = time.monotonic()
        base_elapsed = float(state["elapsed_s"])
        last_save = started
        bar = tqdm(desc=f"epoch {epoch + 1}", unit="batch", disable=not progress, leave=False)
        running = None
        paths = shard_paths(train_dir)  # a dataset still being written grows between epochs
        for x_np, y_np in iterate_batches(paths, config.batch_size, rng, augmentation=config.augmentation):
            if config.crop is not None:
                x_np, y_np = random_crop(x_np, y_np, (config.crop[0], config.crop[1]), rng)
            state["elapsed_s"] = base_elapsed + time.monotonic() - started
            frac = progress_fraction(float(epoch))
            if frac >= 1.0:
                done = True
                break
            for group in optimizer.param_groups:
                group["lr"] = schedule(frac, int(state["step"]), config)
            x = torch.from_numpy(x_np)
            y = torch.from_numpy(y_np.astype(np.float32))[:, None]
            logits = model(x)
            loss = bce_dice_loss(logits, y, config.dice_weight)
            if teacher is not None:
                with torch.no_grad():
                    taught = torch.sigmoid(teacher(x))
                loss = (1.0 - config.teacher_weight) * loss + config.teacher_weight * F.binary_cross_entropy_with_logits(logits, taught)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            state["step"] = int(state["step"]) + 1
            value = float(loss.detach())
            running = value if running is None else 0.95 * running + 0.05 * value
            bar.update(1)
            bar.set_postfix(loss=f"{running:.4f}", lr=f"{optimizer.param_groups[0]['lr']:.2e}")
            if on_step is not None:
                on_step(int(state["step"]), value)
            if time.monotonic() - last_save > config.checkpoint_every_s:
                checkpoint()
                last_save = time.monotonic()
        bar.close()
        state["elapsed_s"] = base_elapsed + time.monotonic() - started
        if not done:
            state["epoch"] = epoch + 1
        validate()
        training_mode(model, freeze_batchnorm=config.freeze_batchnorm)
    summary: dict[str, object] = {
        "steps": state["step"],
        "epochs": state["epoch"],
        "elapsed_s": state["elapsed_s"],
        "best_f1": state["best_f1"],
        "parameters": count_parameters(model),
    }
    log.info("training finished: %s", summary)
    return summary
