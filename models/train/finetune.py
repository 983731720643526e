"""Fine-tuning the shipped network on annotated recordings of your sensor.

The targets come from ``darkread train annotate`` (the page's pose found from its ArUco markers,
``models/train/annotate.py``): shards of the windows the glasses cut, each with the page's ink
under that pose. Fine-tuning then

* starts from the **shipped weights** (``models/binary_unet.onnx``, read back into torch by
  ``onnx_weights.py`` and checked to give the same logits);
* keeps the BatchNorms frozen (the annotated windows are few and correlated; their batch
  statistics would overwrite the synthetic ones);
* leaves out of the loss the pixels an annotated window's ``ignore`` mask marks (the page's
  markers: no page a user reads carries them, so the network must not learn to draw them);
* mixes **synthetic standard-regime windows** into every batch (``synthetic_share``), so what the
  network knew of the simulator, and of light levels the recordings do not cover, is not
  forgotten;
* optionally **anchors** those synthetic windows to what the starting network itself said of them
  (``anchor_weight``: a frozen copy's ink probability as a second target, "learning without
  forgetting"): the truth alone lets the network drift wherever the truth and its old answer
  differ, which on the original regime is mostly the faint, uncertain strokes of dim light;
* runs at a low learning rate (AdamW, short warm-up, cosine decay) within a step and time budget;
* exports ONNX that the edge loads as it is (``darkread read --model tuned.onnx``), carrying the
  starting network's ink temperature (without it the edge would read the tuned network at the
  default 1.5 instead of the shipped 1.0 and keep twice as many frames: a different edge, not a
  different network; ``darkread train calibrate --store`` sets another).
"""

from __future__ import annotations

import copy
import json
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.models.synth.session import SessionSpec
from darkread.models.synth.shards import SAMPLES_PER_PAGE, make_samples, shard_seed
from darkread.models.train.annotate import SHARD_NAME, annotate_recording
from darkread.models.train.calibrate import store_ink_temperature, stored_ink_temperature
from darkread.models.train.data import Shard, augment, concat_shards, count_samples, labels, load_dataset, random_crop, split_labels
from darkread.models.train.export import export_onnx
from darkread.models.train.fit import bce_dice_loss, evaluate_model, frozen, training_mode
from darkread.models.train.onnx_weights import max_output_difference, model_from_onnx

log = logging.getLogger(__name__)

ROUND_TRIP_TOLERANCE = 1e-3  # largest logit difference accepted between torch and onnxruntime


class FinetuneError(ValueError):
    """Nothing to tune on, or a model that does not round-trip."""


@dataclass(frozen=True)
class TuneConfig:
    lr: float = 2e-4  # peak; ~15x below the training rate (3e-3)
    steps: int = 1500
    minutes: float = 20.0  # wall-time budget; whichever of steps and minutes ends first
    batch_size: int = 16
    synthetic_share: float = 0.5  # of every batch
    warmup_steps: int = 50
    crop: tuple[int, int] | None = (64, 128)  # as the shipped training (the net is fully convolutional)
    max_shift: int = 6
    dice_weight: float = 0.5
    threads: int = 1
    seed: int = 0
    monitor_windows: int = 96  # per kind, scored before and after (logged; the real test is `train compare`)
    anchor_weight: float = 0.0  # weight of the starting network's own answer on the synthetic windows (0 = off)
    train_only: tuple[str, ...] = ()  # top-level modules to tune (e.g. ("stem", "down1")); empty = all


def check_parts(model: Any, train_only: Sequence[str]) -> None:
    """Refuse a ``--train-only`` part the network does not have, naming the parts it has."""
    known = {name for name, _ in model.named_children()}
    unknown = sorted(set(train_only) - known)
    if unknown:
        raise ValueError(f"--train-only {','.join(unknown)}: no such part of the network (it has {', '.join(sorted(known))})")


def trainable_parameters(model: Any, train_only: Sequence[str]) -> list[Any]:
    """The parameters of the named top-level modules (all of them when none are named); the rest are
    frozen, so a sensor's low-level difference can be learned where it enters and nowhere else."""
    if not train_only:
        return list(model.parameters())
    check_parts(model, train_only)
    chosen = []
    for name, parameter in model.named_parameters():
        keep = name.split(".", 1)[0] in train_only
        parameter.requires_grad_(keep)
        if keep:
            chosen.append(parameter)
    return chosen


def lr_at(step: int, cfg: TuneConfig, progress: float) -> float:
    """Linear warm-up, then cosine decay to 5 % of the peak over the budget."""
    warm = min(1.0, (step + 1) / max(1, cfg.warmup_steps))
    return cfg.lr * warm * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, progress))))


def load_annotated(dirs: Sequence[str | Path]) -> tuple[Shard, dict[str, int]]:
    """Every window of the annotated shard directories ``train annotate`` wrote, and a count per directory."""
    parts, counts = [], {}
    for d in dirs:
        path = Path(d)
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such annotated directory")
        shard = load_dataset(path)
        parts.append(shard)
        counts[str(path)] = len(shard)
    if not parts or sum(counts.values()) == 0:
        raise FinetuneError("no annotated windows to tune on")
    return concat_shards(parts), counts


def synthetic_windows(n: int, sources: Sequence[str | Path] = (), seed: int = 0, progress: bool = True) -> Shard:
    """``n`` standard-regime windows: from shard directories taken in turn until ``n`` are loaded
    (``darkread synth dataset``'s random crops; ``darkread train rehearsal``'s windows of simulated
    reading, which are what the glasses cut), or simulated now."""
    if n <= 0:
        return Shard(np.zeros((0, 4, 100, 200), np.float16), np.zeros((0, 100, 200), np.uint8), {})
    if sources:
        parts: list[Shard] = []
        for source in sources:
            left = n - sum(len(p) for p in parts)
            if left <= 0:
                break
            parts.append(load_dataset(source, limit=left))
        return Shard(np.concatenate([p.voxels for p in parts]), np.concatenate([p.targets for p in parts]), {})
    from tqdm import tqdm


    spec = SessionSpec(split="train", duration_s=4.0)
    vs: list[np.ndarray] = []
    ts: list[np.ndarray] = []
    with tqdm(total=n, desc="synthetic windows", unit="window", disable=not progress) as bar:
        page = 0
        while sum(len(v) for v in vs) < n:
            k = min(SAMPLES_PER_PAGE, n - sum(len(v) for v in vs))
            v, t, _ = make_samples(spec, shard_seed(seed, "finetune", False, 0, page), k)
            vs.append(v)
            ts.append(t)
            bar.update(k)
            page += 1
    return Shard(np.concatenate(vs), np.concatenate(ts), {})


def _batch(pool: Shard, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``k`` random windows: float32 voxels and label arrays (``data.labels``: ignored pixels marked)."""
    take = rng.choice(len(pool), size=k, replace=len(pool) < k)
    return pool.voxels[take].astype(np.float32), labels(pool.targets[take], None if pool.ignore is None else pool.ignore[take])


def tune(model: Any, annotated: Shard, synthetic: Shard, cfg: TuneConfig, *, anchor: Any = None,
         progress: bool = True) -> dict[str, Any]:
    """Train ``model`` in place on batches mixing both pools; returns the loss history and what ran.

    ``anchor`` (a frozen network, used when ``cfg.anchor_weight`` > 0) gives the synthetic rows a
    second target: its own ink probability, weighted ``cfg.anchor_weight`` against the truth.
    """
    import torch
    import torch.nn.functional as F
    from tqdm import tqdm


    if len(annotated) == 0:
        raise FinetuneError("no annotated windows to tune on")
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    n_syn = int(round(cfg.batch_size * cfg.synthetic_share)) if len(synthetic) else 0
    n_ann = cfg.batch_size - n_syn
    optimizer = torch.optim.AdamW(trainable_parameters(model, cfg.train_only), lr=cfg.lr, weight_decay=0.0)
    training_mode(model, freeze_batchnorm=True)
    budget_s, started = cfg.minutes * 60.0, time.perf_counter()
    losses: list[float] = []
    step = 0
    bar = tqdm(total=cfg.steps, desc="fine-tuning", unit="step", disable=not progress)
    while step < cfg.steps:
        elapsed = time.perf_counter() - started
        if elapsed >= budget_s:
            log.info("time budget (%.1f min) reached after %d steps", cfg.minutes, step)
            break
        for group in optimizer.param_groups:
            group["lr"] = lr_at(step, cfg, max(step / cfg.steps, elapsed / budget_s))
        xs, ys = zip(*[_batch(pool, k, rng) for pool, k in ((annotated, n_ann), (synthetic, n_syn)) if k > 0])
        x, y = augment(np.concatenate(xs), np.concatenate(ys), rng, max_shift=cfg.max_shift)
        if cfg.crop is not None:
            x, y = random_crop(x, y, cfg.crop, rng)
        y, valid = split_labels(y)
        x_t = torch.from_numpy(np.ascontiguousarray(x))
        logits = model(x_t)
        loss = bce_dice_loss(logits, torch.from_numpy(y.astype(np.float32))[:, None], cfg.dice_weight,
                             torch.from_numpy(valid.astype(np.float32))[:, None])
        if anchor is not None and cfg.anchor_weight > 0 and n_syn > 0:
            # the batch is the annotated rows, then the synthetic ones (augment and crop keep the order)
            with torch.no_grad():
                said = torch.sigmoid(anchor(x_t[n_ann:]))
            loss = loss + cfg.anchor_weight * F.binary_cross_entropy_with_logits(logits[n_ann:], said)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
        step += 1
        bar.update(1)
        if step % 25 == 0:
            bar.set_postfix(loss=f"{np.mean(losses[-25:]):.3f}")
    bar.close()
    model.eval()
    return {"steps": step, "seconds": round(time.perf_counter() - started, 1), "batch": {"annotated": n_ann, "synthetic": n_syn},
            "loss_first_25": float(np.mean(losses[:25])) if losses else None,
            "loss_last_25": float(np.mean(losses[-25:])) if losses else None}


def spread_indices(total: int, n: int) -> np.ndarray:
    """``n`` indices spread evenly over ``range(total)`` (all of them when ``total`` <= ``n``): the
    annotated windows come recording after recording, so the first ``n`` would all be one recording's."""
    if total <= n:
        return np.arange(total)
    return np.unique(np.linspace(0, total - 1, n).round().astype(np.int64))


def _monitor(model: Any, pools: dict[str, Shard], n: int) -> dict[str, float]:

    scores = {}
    for name, pool in pools.items():
        if len(pool):
            take = spread_indices(len(pool), n)
            scores[name] = round(evaluate_model(model, pool.voxels[take], pool.targets[take],
                                                ignore=None if pool.ignore is None else pool.ignore[take])["f1"], 4)
    return scores


def annotate_missing(recordings: Sequence[str | Path], layout: str | Path | None, root: Path, progress: bool) -> list[Path]:
    """Annotate recordings not yet annotated under ``root``; returns their annotated directories."""

    out = []
    for rec in recordings:
        target = root / Path(rec).name
        if not (target / SHARD_NAME).is_file():
            log.info("annotating %s -> %s", rec, target)
            annotate_recording(rec, layout, target, progress=progress)
        out.append(target)
    return out


def finetune(
    annotated_dirs: Sequence[str | Path],
    base_model: str | Path,
    run_dir: str | Path,
    export_to: str | Path | None = None,
    *,
    cfg: TuneConfig = TuneConfig(),
    synthetic: int | None = 600,
    synthetic_dirs: Sequence[str | Path] = (),
    progress: bool = True,
) -> dict[str, Any]:
    """Fine-tune ``base_model`` (ONNX) on the annotated windows plus synthetic ones; export ONNX."""
    import torch


    annotated, counts = load_annotated(annotated_dirs)
    log.info("%d annotated windows from %d directories", len(annotated), len(counts))
    model = model_from_onnx(base_model)
    probe = annotated.voxels[: min(4, len(annotated))].astype(np.float32)
    round_trip = max_output_difference(model, base_model, probe)
    if round_trip > ROUND_TRIP_TOLERANCE:
        raise FinetuneError(f"{base_model}: torch and onnxruntime logits differ by {round_trip:.3g} after loading")
    if synthetic is None and not synthetic_dirs:
        raise FinetuneError("--synthetic all takes every window of --synthetic-dir: give the directories")
    wanted = sum(count_samples(d) for d in synthetic_dirs) if synthetic is None else synthetic + cfg.monitor_windows
    syn = synthetic_windows(wanted, synthetic_dirs, seed=cfg.seed + 1, progress=progress)
    monitored = min(cfg.monitor_windows, len(syn))
    syn_monitor, syn_train = syn.select(np.arange(monitored)), syn.select(np.arange(monitored, len(syn)))
    pools = {"annotated_training_windows": annotated, "synthetic_held_out": syn_monitor}
    before = _monitor(model, pools, cfg.monitor_windows)
    anchor = frozen(copy.deepcopy(model)) if cfg.anchor_weight > 0 else None
    run = tune(model, annotated, syn_train, cfg, anchor=anchor, progress=progress)
    after = _monitor(model, pools, cfg.monitor_windows)
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    onnx_path = Path(export_to) if export_to is not None else out / "tuned.onnx"
    export_onnx(model, onnx_path)
    temperature = stored_ink_temperature(base_model)
    if temperature is not None:
        store_ink_temperature(onnx_path, temperature)
    exported = max_output_difference(model, onnx_path, probe)
    summary = {
        "base_model": str(base_model),
        "exported": str(onnx_path),
        "annotated": counts,
        "annotated_windows": len(annotated),
        "annotated_ignored_pixel_share": round(float(annotated.ignore.mean()), 4) if annotated.ignore is not None else 0.0,
        "synthetic_windows": len(syn_train),
        "synthetic_source": ", ".join(map(str, synthetic_dirs)) if synthetic_dirs else "simulated (standard regime, training texts)",
        "ink_temperature": temperature,  # the starting network's, carried over (None: the edge's default)
        "round_trip_max_logit_difference": {"shipped_onnx_to_torch": round_trip, "torch_to_exported_onnx": exported},
        "monitor_f1_before": before,
        "monitor_f1_after": after,
        **run,
        "config": asdict(cfg),
    }
    torch.save({"model": model.state_dict(), "finetune": summary}, out / "tuned.pt")
    (out / "finetune.json").write_text(json.dumps(summary, indent=1, default=float) + "\n", encoding="utf-8")
    return summary
