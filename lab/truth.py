"""The simulator's truth about a synthetic recording, in one place: the page's pose over time
(``pose_truth.npz``), the page's ink (``page_ink.npz`` or a marker page's ``page.layout.json``), and
what follows from them: each window's true ink, and windows labelled for tuning.

The lab scores with it (evaluation, attribution, comparisons, the true-motion read); the product never
sees it: a real recording has no truth.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.edge.io.calibration import load_calibration
from darkread.edge.io.recording import open_recording
from darkread.models.synth.marker_page import load_layout
from darkread.models.synth.recording import LAYOUT_NAME, load_page_ink, load_pose_truth
from darkread.models.synth.shards import SampleMeta, write_shard
from darkread.models.train.annotate import (
    SHARD_NAME,
    SUMMARY_NAME,
    AnnotationError,
    page_ink_for_pose,
    render_target,
    window_rays,
)
from darkread.models.train.windows import Windows, read_events, window_stack


@dataclass(frozen=True)
class PageTruth:
    """What the simulator knows of a recording: the page ink raster, its scale and the pose over time."""

    ink: np.ndarray  # float32 coverage 0..1, page raster
    px_per_mm: float
    pose_at: Callable[[float], np.ndarray]  # t_us -> page mm -> normalised-camera homography
    calibration: Any


def load_truth(recording: Path) -> PageTruth | None:
    """The recording's truth files, or None when it has none (a real recording)."""
    loaded = load_truth_and_pose(recording)
    return None if loaded is None else loaded[0]


def load_truth_and_pose(recording: Path) -> tuple[PageTruth, Any] | None:
    """``load_truth`` and the per-millisecond pose behind its ``pose_at`` (``PoseTruth``)."""
    ink_path = recording / "page_ink.npz"
    pose = load_pose_truth(recording)
    if pose is None or not ink_path.is_file():
        return None
    with np.load(ink_path) as z:
        ink, px_per_mm = z["ink"].astype(np.float32), float(z["px_per_mm"])
    return PageTruth(ink, px_per_mm, pose.at, load_calibration(recording / "calibration.json")), pose


@dataclass
class ScoredWindows:
    """Voxel grids and their true ink, from a recording or a shard directory."""

    voxels: np.ndarray  # float [n,4,100,200]
    targets: np.ndarray | None  # uint8 [n,100,200], None when no ground truth exists
    source: str  # where the targets come from
    ignore: np.ndarray | None = None  # uint8 [n,100,200], 1 = not scored (an annotated shard's markers)
    windows: Windows | None = None  # a recording's windows as cut (origins, end times, events)


def is_recording(path: Path) -> bool:
    return (path / "events.raw").is_file() or any(path.glob("*.raw"))


InkSource = Callable[[np.ndarray, Any], tuple[np.ndarray, float]]  # (page -> camera H, calibration) -> (ink, px per mm)


def page_ink_source(recording: Path) -> InkSource | None:
    """The simulator's page ink in ``pose_truth.npz``'s millimetre frame, at a scale fit for a pose.

    A marker page is re-created from ``page.layout.json`` and resampled to ~1.25 texels per sensor
    pixel (as the simulator's texture); a plain page's texture is ``page_ink.npz`` itself.
    """
    if (recording / LAYOUT_NAME).is_file():
        return page_ink_for_pose(load_layout(recording / LAYOUT_NAME))
    plain = load_page_ink(recording)
    return None if plain is None else (lambda H, calib: plain)


def truth_windows(recording: str | Path, every_ms: float = 40.0, max_windows: int = 400, deblur: bool = False,
                  denoise: bool = False) -> ScoredWindows:
    """The recording's windows with the simulator's ink under the true pose (targets None without it);
    ``deblur``, ``denoise``: the windows' events deblurred and denoised as on the edge (``window_stack``)."""
    path = Path(recording)
    rec, events, wh = read_events(path)
    windows = window_stack(rec, events, wh, every_ms=every_ms, max_windows=max_windows, deblur=deblur, denoise=denoise)
    truth = load_pose_truth(path)
    ink = page_ink_source(path)
    if truth is None or ink is None or len(windows.t_end_us) == 0:
        return ScoredWindows(windows.voxels, None, "none (no pose_truth.npz with page.layout.json or page_ink.npz)", windows=windows)
    targets = np.zeros((len(windows.t_end_us), *windows.voxels.shape[-2:]), np.uint8)
    for i, (t_end, origin) in enumerate(zip(windows.t_end_us, windows.origins)):
        H = truth.at(float(t_end))  # page mm -> camera point: a page -> normalised-image homography
        page_ink, s = ink(H, rec.calibration)
        targets[i] = render_target(page_ink, s, H, window_rays(rec.calibration, tuple(origin)))
    return ScoredWindows(windows.voxels, targets, "simulator's true pose", windows=windows)


def annotate_from_truth(recording: str | Path, out: str | Path, every_ms: float = 40.0, max_windows: int = 400,
                        deblur: bool = True, denoise: bool = True) -> dict[str, Any]:
    """A synthetic recording's windows labelled from the simulator's own pose and ink (no markers
    needed: any plain page ``synth recording`` wrote), deblurred and denoised as the edge does them; writes
    the shard and summary as ``annotate_recording`` does. For tuning on the windows the glasses cut
    while a simulated reader reads (fixations, saccades, head motion), not on random crops."""
    recording = Path(recording)
    scored = truth_windows(recording, every_ms=every_ms, max_windows=max_windows, deblur=deblur, denoise=denoise)
    windows = scored.windows
    assert windows is not None  # truth_windows keeps them
    if len(windows.t_end_us) == 0:
        raise AnnotationError(f"{recording}: no windows to annotate (no gaze, or too few events)")
    if scored.targets is None:
        raise AnnotationError(f"{recording}: no simulator truth (pose_truth.npz with page_ink.npz or page.layout.json): "
                              "only a recording `darkread synth recording` made can be annotated with --truth")
    meta = open_recording(recording).meta
    metas = [SampleMeta(lux=float(meta.get("lux", 0.0)), motion=str(meta.get("motion", "")), kind=str(meta.get("text_kind", "")),
                        font=str(meta.get("font", "")), xheight_px=float(meta.get("xheight_px", 0.0)), seed=int(meta.get("seed", 0)),
                        x0=int(o[0]), y0=int(o[1]), t_end_us=int(t), n_events=len(events))
             for o, t, events in zip(windows.origins, windows.t_end_us, windows.events)]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_shard(out / SHARD_NAME, scored.voxels, scored.targets, metas)
    summary: dict[str, Any] = {
        "recording": str(recording),
        "source": scored.source,
        "lux": meta.get("lux"),
        "motion": meta.get("motion"),
        "windows": int(len(scored.targets)),
        "annotated": int(len(scored.targets)),
        "annotated_share": 1.0,
        "ink_share": round(float(scored.targets.mean()), 4),
        "deblurred": bool(deblur),
        "denoised": bool(denoise),
        "every_ms": every_ms,
    }
    (out / SUMMARY_NAME).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary
