"""The windows the glasses would reconstruct from a recording, cut exactly as on the edge
(gaze -> fovea -> newest 1600 events -> voxel grid): what annotation labels, fine-tuning learns
from and the before/after comparison scores.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.edge.config import PipelineConfig
from darkread.edge.deblur import DeblurConfig
from darkread.edge.denoise import DenoiseConfig
from darkread.edge.fovea import window_events, window_origin
from darkread.edge.frame import clean_window
from darkread.edge.gaze import GazeMapper
from darkread.edge.io.evt3 import decode_evt3
from darkread.edge.io.raw_header import read_raw_header
from darkread.edge.io.recording import open_recording
from darkread.edge.voxel import VoxelConfig, voxel_grid
from darkread.edge.windows import MAX_HISTORY_EVENTS

WINDOW_HW: tuple[int, int] = (100, 200)


@dataclass
class Windows:
    """The windows the glasses would reconstruct: voxel grids, origins, end times, their events."""

    voxels: np.ndarray  # float32 [n, 4, 100, 200]
    origins: np.ndarray  # int [n, 2] (x0, y0)
    t_end_us: np.ndarray  # int64 [n]
    events: list[np.ndarray]  # each window's events as binned (after the deblur and the denoise asked for)
    raw: list[np.ndarray]  # ... and as the sensor gave them (the page over their span)


def read_events(path: str | Path, *, need_text: bool = False) -> tuple[Any, np.ndarray, tuple[int, int]]:
    """(recording, all its events, sensor (width, height)); raises for a recording without events."""

    rec = open_recording(path)
    if need_text and not rec.text:
        raise ValueError(f"{path}: no printed text (text.txt)")
    header = read_raw_header(rec.raw_path)
    events, _ = decode_evt3(rec.raw_path.read_bytes()[header.data_offset :], header.width, header.height)
    if len(events) == 0:
        raise ValueError(f"{path}: no events")
    return rec, events, (header.width, header.height)


def window_stack(rec: Any, events: np.ndarray, sensor_wh: tuple[int, int], every_ms: float = 40.0,
                 max_windows: int = 400, deblur: bool = False, denoise: bool = False) -> Windows:
    """Every ``every_ms`` a window cut exactly as on the edge: gaze -> fovea -> newest 1600 events -> voxels.

    ``deblur``: each window's events moved back along the head's motion as the edge does before its
    voxel grid (``edge.deblur``), so a network tuned on these windows sees what it will be given;
    ``denoise``: a dim-light window's isolated events dropped as the edge drops them (``edge.denoise``)."""

    mapper = GazeMapper(rec.calibration, rec.gaze())
    deblur_cfg, denoise_cfg = DeblurConfig(enabled=deblur), DenoiseConfig(enabled=denoise)
    n_events, voxel = PipelineConfig().n_events, VoxelConfig()
    times = np.arange(int(events["t"][0]) + 100_000, int(events["t"][-1]), int(every_ms * 1000))[:max_windows]
    ends = np.searchsorted(events["t"], times, side="right")
    voxels, origins, t_end, chosen, raw = [], [], [], [], []
    for t, end in zip(times, ends):
        gaze = mapper.at(int(t))
        if gaze is None:
            continue
        origin = window_origin(gaze.pixel, sensor_wh, voxel.fovea)
        recent = events[max(0, end - MAX_HISTORY_EVENTS) : end]
        sensed = window_events(recent, origin, voxel.fovea, n_events)
        window, _, _ = clean_window(sensed, recent, origin, WINDOW_HW, sensor_wh, deblur_cfg, denoise_cfg)
        if len(window) >= n_events // 2:
            voxels.append(voxel_grid(window, origin[0], origin[1], voxel))
            origins.append(origin)
            t_end.append(int(sensed["t"][-1]))  # (the deblur's reference: the newest event, even if the denoise dropped it)
            chosen.append(window)
            raw.append(sensed)
    stack = np.stack(voxels).astype(np.float32) if voxels else np.zeros((0, 4, *WINDOW_HW), np.float32)
    return Windows(stack, np.array(origins, dtype=np.int64).reshape(-1, 2), np.array(t_end, dtype=np.int64), chosen, raw)
