"""Fine-tuning on real recordings of known pages, with targets made automatically.

For each recording the windows the glasses would reconstruct are cut exactly as on the edge
(gaze -> fovea -> newest 1600 events -> voxel grid). Each window's target comes from the page
whose text is known (``text.txt``):

1. the page is rendered as an ink image at the recording's x-height (``meta.json``);
2. the current model's prediction for the window is located on that page by normalised
   cross-correlation over a few scales (``match_target``);
3. a confident match gives the page crop under the window as the target; an unconfident one
   drops the window (a wrong target teaches the wrong thing, a missing one costs nothing).

The network is then trained on those pairs at a learning rate ~1000x below the training rate,
so it adapts to the real sensor's noise without forgetting the synthetic prior.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

log = logging.getLogger(__name__)

WINDOW_HW: tuple[int, int] = (100, 200)


@dataclass(frozen=True)
class Match:
    target: np.ndarray  # uint8 [100,200], 1 = ink
    score: float  # normalised cross-correlation in [-1, 1]
    x: int  # top-left of the window on the scaled page
    y: int
    scale: float  # page scale at which the prediction fitted best


def render_page_ink(text: str, xheight_px: float, font_path: str | Path | None = None, margin_px: int = 120) -> np.ndarray:
    """The printed page as an ink mask (uint8, 1 = ink) with the given x-height in pixels."""
    from PIL import Image, ImageDraw, ImageFont

    path = str(font_path) if font_path else _default_font()
    probe = ImageFont.truetype(path, 100)
    _, top, _, bottom = probe.getbbox("x", anchor="ls")
    size = max(4, round(xheight_px * 100 / max(1, bottom - top)))
    font = ImageFont.truetype(path, size)
    lines = [line.rstrip() for line in text.splitlines()] or [""]
    pitch = round(size * 1.4)
    width = int(max(font.getlength(line) for line in lines)) + 2 * margin_px
    height = pitch * len(lines) + 2 * margin_px
    image = Image.new("L", (width, height), 0)
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((margin_px, margin_px + size * 0.8 + i * pitch), line, fill=255, font=font, anchor="ls")
    return (np.asarray(image) > 127).astype(np.uint8)


def _default_font() -> str:
    import matplotlib

    return str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf")


def _font_for(meta: dict[str, Any]) -> str | None:
    name = meta.get("font")
    if not name:
        return None
    try:
        from darkread.models.synth.fonts import face_by_name

        return str(face_by_name(str(name)).path)
    except (ImportError, ValueError, OSError):  # unknown name or synth component absent: the default face still matches roughly
        return None


def match_target(
    prediction: np.ndarray,
    page_ink: np.ndarray,
    scales: Sequence[float] = (0.8, 0.9, 1.0, 1.1, 1.25),
    min_score: float = 0.35,
    min_ink_fraction: float = 0.01,
) -> Match | None:
    """Where on the page ``prediction`` fits best; the page crop there is the target.

    Returns None when the prediction has too little ink to locate, or no position correlates
    better than ``min_score``.
    """
    pred = np.asarray(prediction, np.float32)
    h, w = pred.shape
    if pred.mean() < min_ink_fraction:
        return None
    best: Match | None = None
    for scale in scales:
        page = cv2.resize(page_ink.astype(np.float32), None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        if page.shape[0] < h or page.shape[1] < w:
            continue
        response = cv2.matchTemplate(page, pred, cv2.TM_CCOEFF_NORMED)
        # Nearly blank page patches have ~zero variance and normalise to meaningless scores.
        patch_ink = cv2.matchTemplate(page, np.ones_like(pred), cv2.TM_CCORR)
        response[~np.isfinite(response) | (patch_ink < 0.3 * pred.sum())] = -1.0
        _, score, _, (x, y) = cv2.minMaxLoc(response)
        if np.isfinite(score) and (best is None or score > best.score):
            target = (page[y : y + h, x : x + w] > 0.5).astype(np.uint8)
            best = Match(target=target, score=float(score), x=int(x), y=int(y), scale=float(scale))
    if best is None or best.score < min_score:
        return None
    return best


@dataclass
class Windows:
    """The windows the glasses would reconstruct: voxel grids, origins, end times, their events."""

    voxels: np.ndarray  # float32 [n, 4, 100, 200]
    origins: np.ndarray  # int [n, 2] (x0, y0)
    t_end_us: np.ndarray  # int64 [n]
    events: list[np.ndarray]


def read_events(path: str | Path, *, need_text: bool = True) -> tuple[Any, np.ndarray, tuple[int, int]]:
    """(recording, all its events, sensor (width, height)); raises for a recording without events."""
    from darkread.edge.io.evt3 import decode_evt3
    from darkread.edge.io.raw_header import read_raw_header
    from darkread.edge.io.recording import open_recording

    rec = open_recording(path)
    if need_text and not rec.text:
        raise ValueError(f"{path}: fine-tuning needs the printed text (text.txt)")
    header = read_raw_header(rec.raw_path)
    events, _ = decode_evt3(rec.raw_path.read_bytes()[header.data_offset :], header.width, header.height)
    if len(events) == 0:
        raise ValueError(f"{path}: no events")
    return rec, events, (header.width, header.height)


def window_stack(rec: Any, events: np.ndarray, sensor_wh: tuple[int, int], every_ms: float = 40.0,
                 max_windows: int = 400) -> Windows:
    """Every ``every_ms`` a window cut exactly as on the edge: gaze -> fovea -> newest 1600 events -> voxels."""
    from darkread.edge.config import PipelineConfig
    from darkread.edge.fovea import window_events, window_origin
    from darkread.edge.gaze import GazeMapper
    from darkread.edge.pipeline import MAX_HISTORY_EVENTS
    from darkread.edge.voxel import VoxelConfig, voxel_grid

    mapper = GazeMapper(rec.calibration, rec.gaze())
    n_events, voxel = PipelineConfig().n_events, VoxelConfig()
    times = np.arange(int(events["t"][0]) + 100_000, int(events["t"][-1]), int(every_ms * 1000))[:max_windows]
    ends = np.searchsorted(events["t"], times, side="right")
    voxels, origins, t_end, chosen = [], [], [], []
    for t, end in zip(times, ends):
        gaze = mapper.at(int(t))
        if gaze is None:
            continue
        origin = window_origin(gaze.pixel, sensor_wh, voxel.fovea)
        window = window_events(events[max(0, end - MAX_HISTORY_EVENTS) : end], origin, voxel.fovea, n_events)
        if len(window) >= n_events // 2:
            voxels.append(voxel_grid(window, origin[0], origin[1], voxel))
            origins.append(origin)
            t_end.append(int(window["t"][-1]))
            chosen.append(window)
    stack = np.stack(voxels).astype(np.float32) if voxels else np.zeros((0, 4, *WINDOW_HW), np.float32)
    return Windows(stack, np.array(origins, dtype=np.int64).reshape(-1, 2), np.array(t_end, dtype=np.int64), chosen)


def recording_windows(path: str | Path, every_ms: float = 40.0, max_windows: int = 400) -> tuple[np.ndarray, dict[str, Any], str]:
    """Voxel grids [n,4,100,200] the edge would reconstruct from ``path``, its meta and its text."""
    rec, events, sensor_wh = read_events(path)
    windows = window_stack(rec, events, sensor_wh, every_ms, max_windows)
    return windows.voxels, rec.meta, rec.text


def make_targets(
    voxels: np.ndarray, predictions: np.ndarray, page_ink: np.ndarray, min_score: float = 0.35
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Keep the windows whose prediction matches the page; returns voxels, targets, scores."""
    kept_v, kept_t, scores = [], [], []
    for voxel, pred in zip(voxels, predictions):
        match = match_target(pred, page_ink, min_score=min_score)
        if match is not None:
            kept_v.append(voxel)
            kept_t.append(match.target)
            scores.append(match.score)
    if not kept_v:
        return np.zeros((0, 4, *WINDOW_HW), np.float32), np.zeros((0, *WINDOW_HW), np.uint8), []
    return np.stack(kept_v), np.stack(kept_t), scores


def finetune_arrays(
    model: Any, voxels: np.ndarray, targets: np.ndarray, *, lr: float, steps: int, batch_size: int = 16,
    threads: int = 2, dice_weight: float = 0.5, seed: int = 0,
) -> list[float]:
    """Train ``model`` in place on (voxels, targets) for ``steps`` steps; returns the losses."""
    import torch
    from darkread.models.train.data import augment
    from darkread.models.train.fit import bce_dice_loss

    if len(voxels) == 0:
        raise ValueError("no windows to fine-tune on (no prediction matched the page)")
    torch.set_num_threads(threads)
    rng = np.random.default_rng(seed)
    optimizer = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=0.0)
    model.train()
    for module in model.modules():  # keep the synthetic BatchNorm statistics: real batches are few
        if isinstance(module, torch.nn.BatchNorm2d):
            module.eval()
    losses = []
    for _ in range(steps):
        take = rng.choice(len(voxels), size=min(batch_size, len(voxels)), replace=False)
        x, y = augment(voxels[take].astype(np.float32), targets[take], rng, max_shift=0)
        loss = bce_dice_loss(model(torch.from_numpy(x)), torch.from_numpy(y.astype(np.float32))[:, None], dice_weight)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    model.eval()
    return losses


def finetune_recordings(
    recordings: Sequence[str | Path], checkpoint: str | Path, run_dir: str | Path, *, lr_scale: float = 1e-3,
    steps: int = 200, threads: int = 2, export_to: str | Path | None = None, min_score: float = 0.35,
) -> dict[str, Any]:
    """Targets from each recording's known page, then fine-tuning of ``checkpoint`` at ``lr_scale`` x its lr."""
    import torch
    from darkread.models.train.fit import load_model

    data = torch.load(checkpoint, map_location="cpu", weights_only=False)
    base_lr = float(data["fit_config"]["lr"])
    model = load_model(checkpoint)
    all_v, all_t, summary = [], [], {}
    for path in recordings:
        voxels, meta, text = recording_windows(path)
        with torch.no_grad():
            preds = np.concatenate([(model(torch.from_numpy(voxels[i : i + 32])) > 0)[:, 0].numpy() for i in range(0, len(voxels), 32)]) if len(voxels) else np.zeros((0, *WINDOW_HW), bool)
        page = render_page_ink(text, float(meta.get("xheight_px", 10.0)), _font_for(meta))
        kept_v, kept_t, scores = make_targets(voxels, preds.astype(np.uint8), page, min_score)
        summary[str(path)] = {"windows": len(voxels), "matched": len(kept_v), "mean_score": float(np.mean(scores)) if scores else None}
        log.info("%s: %d windows, %d matched the page", path, len(voxels), len(kept_v))
        all_v.append(kept_v)
        all_t.append(kept_t)
    voxels, targets = np.concatenate(all_v), np.concatenate(all_t)
    losses = finetune_arrays(model, voxels, targets, lr=base_lr * lr_scale, steps=steps, threads=threads)
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.save({"model": model.state_dict(), "fit_config": {**data["fit_config"], "lr": base_lr * lr_scale}}, out / "best.pt")
    if export_to is not None:
        from darkread.models.train.export import export_onnx

        export_onnx(model, export_to)
    return {"recordings": summary, "pairs": len(voxels), "lr": base_lr * lr_scale, "first_loss": losses[0], "last_loss": losses[-1]}
