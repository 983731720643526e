"""Where a page's reading errors come from: the network's frames, the stitcher's placement, or the OCR.

For a synthetic recording the simulator wrote down the page's true pose (``pose_truth.npz``) and its
ink (``page_ink.npz``). Beside the page the cloud stitched from the frames a ``darkread read`` stored,
two more pages are read by the same OCR, both on the page's own raster:

* ``placed``: the same frames, each placed where the true pose puts it (perfect stitching);
* ``ideal``: the true ink of each frame's window, placed the same way (perfect frames and stitching).

And the recording is read once more end to end with the head's motion known exactly
(the edge given the simulator's pose: each window deblurred and each view predicted from the
simulator's pose, ``eval.true_motion``), which tells the errors the head's motion causes in the
dark (what an inertial sensor could remove) from the frames' own.

``stitched`` close to ``placed`` means the stitcher is not what fails; ``placed`` far above
``ideal`` means the frames are. Each frame is also scored against its window's true ink (recall: the
share of true ink with a predicted pixel within 1 px; precision: the converse), which tells missing
strokes from spurious ones. Frames are matched to the pose at their ``t_us``.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from darkread.cloud.store.sqlite import SqliteStore
from darkread.core.text_metrics import error_rates
from darkread.lab.eval.runner import RESULT_NAME, make_ocr_backend, network_digest
from darkread.lab.eval.tables import page_as_section
from darkread.lab.eval.true_motion import TrueHeadMotion
from darkread.lab.truth import PageTruth, load_truth
from darkread.models.train.annotate import page_coordinates, project_page, render_target, window_rays
from darkread.read import read_recording

log = logging.getLogger(__name__)

ATTRIBUTION_NAME = "attribution.md"
CACHE_NAME = "attribution.json"  # per recording, beside its result.json: a rerun (or a larger suite) reuses it
TOLERANCE_PX = 1  # ink within this many pixels counts as found (strokes are ~2 px wide)
TRUE_MOTION_DIR = "true_motion"  # beside a recording's read: its read with the head's motion known exactly
PAGE_GAIN = 2.0  # placed pages: mean ink share x this, clipped (a stroke seen in half the frames is black)


@dataclass(frozen=True)
class Attribution:
    """One recording's three readings (CER, 0..1, clipped at 1) and its frames' ink scores."""

    name: str
    lux: float
    motion: str
    frames: int
    cer_stitched: float
    cer_placed: float
    cer_ideal: float
    frame_recall: float
    frame_precision: float
    cer_true_motion: float | None = None  # read again with the head's motion known exactly


def evaluated_runs(suite: Path, work: Path) -> list[Path]:
    """The run folders of ``work`` that hold a read's stored frames (``<name>/read/cloud``), by name;
    FileNotFoundError, saying how to make them, when there are none."""
    runs = sorted(p for p in work.iterdir() if (p / "read" / "cloud").is_dir()) if work.is_dir() else []
    if not runs:
        raise FileNotFoundError(f"{work}: no evaluated recordings; run `darkread eval run {suite} --work {work}` first")
    return runs


def stored_frames(cloud_dir: Path) -> list[Any]:
    """Every frame of the one session a ``darkread read`` stored in ``cloud_dir`` (SQLite), in order."""

    async def read() -> list[Any]:
        store = SqliteStore(cloud_dir)
        try:
            sessions = await store.sessions()
            if len(sessions) != 1:
                raise ValueError(f"{cloud_dir}: expected the one session of a `darkread read`, found {len(sessions)}")
            frames: list[Any] = []
            while True:
                batch = await store.frames(sessions[0].session_id, after_seq=frames[-1].seq if frames else -1)
                if not batch:
                    return frames
                frames.extend(batch)
        finally:
            await store.close()

    return asyncio.run(read())


@dataclass(frozen=True)
class Placement:
    """Where one window lies on the page raster under the true pose: the raster box it can see
    (row0, row1, col0, col1) and, for each texel of it, the window pixel it samples."""

    box: tuple[int, int, int, int]
    map_x: np.ndarray  # float32 [rows, cols]: window column of each texel
    map_y: np.ndarray  # float32 [rows, cols]: window row
    inside: np.ndarray  # bool [rows, cols]: the texel falls inside the window


def place_window(truth: PageTruth, rays: np.ndarray, origin: tuple[int, int], shape: tuple[int, int],
                 H: np.ndarray) -> Placement | None:
    """The placement of a window (``rays``: its pixels' undistorted rays) under ``H``; None when it sees
    none of the page. Only the box its corners span (2 texels of margin) is projected."""

    h, w = shape
    corners = page_coordinates(H, rays[[0, w - 1, (h - 1) * w, h * w - 1]]) * truth.px_per_mm
    rows, cols = truth.ink.shape
    c0, r0 = np.floor(corners.min(axis=0)).astype(int) - 2
    c1, r1 = np.ceil(corners.max(axis=0)).astype(int) + 2
    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, rows), min(c1, cols)
    if r1 <= r0 or c1 <= c0:
        return None
    gy, gx = np.mgrid[r0:r1, c0:c1].astype(np.float64)
    points = np.c_[(gx.ravel() + 0.5) / truth.px_per_mm, (gy.ravel() + 0.5) / truth.px_per_mm]
    uv = project_page(H, truth.calibration, points).reshape(r1 - r0, c1 - c0, 2)
    map_x = (uv[..., 0] - origin[0]).astype(np.float32)
    map_y = (uv[..., 1] - origin[1]).astype(np.float32)
    inside = (map_x >= 0) & (map_x <= w - 1) & (map_y >= 0) & (map_y <= h - 1)
    return Placement((r0, r1, c0, c1), map_x, map_y, inside)


def compose(masks: Sequence[np.ndarray], placements: Sequence[Placement | None], page_shape: tuple[int, int]) -> np.ndarray:
    """Windows averaged on the page raster at their placements: uint8, black ink on white."""
    total = np.zeros(page_shape, np.float32)
    seen = np.zeros(page_shape, np.float32)
    for mask, placed in zip(masks, placements, strict=True):
        if placed is None:
            continue
        r0, r1, c0, c1 = placed.box
        sampled = cv2.remap(mask.astype(np.float32), placed.map_x, placed.map_y, cv2.INTER_LINEAR, borderValue=0.0)
        total[r0:r1, c0:c1] += sampled * placed.inside
        seen[r0:r1, c0:c1] += placed.inside
    share = np.where(seen > 0, total / np.maximum(seen, 1.0), 0.0)
    return (255.0 * (1.0 - np.clip(share * PAGE_GAIN, 0.0, 1.0))).astype(np.uint8)


def window_truth(truth: PageTruth, rays: np.ndarray, shape: tuple[int, int], H: np.ndarray) -> np.ndarray:
    """The true binary ink of a window (uint8, 1 = ink), as the training targets define it."""

    return render_target(truth.ink, truth.px_per_mm, H, rays, shape)


def ink_found(predicted: np.ndarray, target: np.ndarray, tolerance_px: int = TOLERANCE_PX) -> tuple[int, int, int, int]:
    """(true ink found, true ink, predicted ink near true ink, predicted ink), within ``tolerance_px``."""
    kernel = np.ones((2 * tolerance_px + 1, 2 * tolerance_px + 1), np.uint8)
    pred, true = predicted.astype(np.uint8), target.astype(np.uint8)
    near_pred, near_true = np.asarray(cv2.dilate(pred, kernel), np.uint8), np.asarray(cv2.dilate(true, kernel), np.uint8)
    return (int((true & near_pred).sum()), int(true.sum()), int((pred & near_true).sum()), int(pred.sum()))


def attribute_recording(recording: Path, read_dir: Path, read_page: Callable[[np.ndarray], str]) -> Attribution | None:
    """The three readings and the frame scores of one evaluated recording (None without truth files)."""

    truth = load_truth(recording)
    if truth is None:
        return None
    result = json.loads((read_dir.parent / RESULT_NAME).read_text(encoding="utf-8"))

    frames = stored_frames(read_dir / "cloud")
    masks = [f.mask for f in frames]
    ideal, placements = [], []
    for frame in frames:  # one pose, one set of rays and one placement per frame, for both pages
        origin, H = (int(frame.origin[0]), int(frame.origin[1])), truth.pose_at(float(frame.t_us))
        rays = window_rays(truth.calibration, origin, frame.mask.shape)
        ideal.append(window_truth(truth, rays, frame.mask.shape, H))
        placements.append(place_window(truth, rays, origin, frame.mask.shape, H))
    counts = np.array([ink_found(m, i) for m, i in zip(masks, ideal, strict=True)] or [(0, 0, 0, 0)], np.int64).sum(axis=0)
    reference = (recording / "text.txt").read_text(encoding="utf-8")

    def cer(page: np.ndarray) -> float:
        return min(1.0, error_rates(reference, read_page(page)).cer)

    return Attribution(
        name=recording.name, lux=float(result["lux"]), motion=str(result["motion"]), frames=len(frames),
        cer_stitched=min(1.0, float(result["darkread"].get("cer", 1.0))),
        cer_placed=cer(compose(masks, placements, truth.ink.shape)),
        cer_ideal=cer(compose(ideal, placements, truth.ink.shape)),
        frame_recall=float(counts[0] / max(1, counts[1])), frame_precision=float(counts[2] / max(1, counts[3])),
    )


def _mean(rows: Sequence[Attribution], key: str) -> float:
    return float(np.mean([getattr(row, key) for row in rows]))


def attribution_table(rows: Sequence[Attribution]) -> str:
    """Mean figures per lux and motion (markdown)."""
    groups: dict[tuple[float, str], list[Attribution]] = defaultdict(list)
    for row in rows:
        groups[(row.lux, row.motion)].append(row)
        groups[(row.lux, "all")].append(row)
    order = {"still": 0, "normal": 1, "walking": 2, "all": 3}
    lines = [
        "| lux | motion | n | CER stitched | CER, head motion known exactly | CER frames placed by the true pose "
        "| CER true ink placed so | frame ink recall | frame ink precision |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for (lux, motion), members in sorted(groups.items(), key=lambda kv: (-kv[0][0], order.get(kv[0][1], 9))):
        label = f"**{motion}**" if motion == "all" else motion
        known = [m.cer_true_motion for m in members if m.cer_true_motion is not None]
        true_motion = f"{100 * float(np.mean(known)):.1f}%" if len(known) == len(members) else "–"
        pct = {key: 100 * _mean(members, key) for key in ("cer_stitched", "cer_placed", "cer_ideal", "frame_recall", "frame_precision")}
        lines.append(f"| {lux:g} | {label} | {len(members)} | {pct['cer_stitched']:.1f}% | {true_motion} | {pct['cer_placed']:.1f}% | "
                     f"{pct['cer_ideal']:.1f}% | {pct['frame_recall']:.0f}% | {pct['frame_precision']:.0f}% |")
    return "\n".join(lines)


def cached_attribution(run_dir: Path, backend: str) -> Attribution | None:
    """The attribution stored beside a recording's result, if it is of that result and engine."""

    cache, result = run_dir / CACHE_NAME, run_dir / RESULT_NAME
    if not cache.is_file() or (result.is_file() and result.stat().st_mtime_ns > cache.stat().st_mtime_ns):
        return None
    try:
        stored = json.loads(cache.read_text(encoding="utf-8"))
        if stored.pop("backend", None) != backend:
            return None
        return Attribution(**stored)
    except (ValueError, TypeError, AttributeError):  # truncated or foreign: a cache, so attribute again
        log.warning("%s: unreadable, attributing %s again", cache, run_dir.name)
        return None


def true_motion_cer(recording: Path, run_dir: Path, backend: str, model: str | None = None) -> float:
    """CER of ``recording`` read again end to end, in the mode it was evaluated in, with the head's
    motion known exactly (the simulator's pose as the edge's ``KnownHeadMotion``; kept in ``run_dir/true_motion``). ValueError
    when ``model`` is not the network the recording was evaluated with."""

    result = json.loads((run_dir / RESULT_NAME).read_text(encoding="utf-8"))
    if result.get("model") not in (None, network_digest(model)):
        raise ValueError(f"{run_dir.name} was evaluated with network {result['model']}, not {network_digest(model)}: "
                         "pass the same --model")
    known_motion = TrueHeadMotion.from_recording(recording)
    read = read_recording(recording, backend=backend, model=model, out_dir=run_dir / TRUE_MOTION_DIR,
                          infer=result.get("infer"), known_motion=known_motion)
    return min(1.0, float(read.cer if read.cer is not None else 1.0))


def write_attribution(suite: Path, work: Path, out: Path, *, backend: str = "local", progress: bool = True,
                      notes: Sequence[str] = (), model: str | None = None) -> Path:
    """Attribute every evaluated recording of ``suite`` (results in ``work``, read by ``model``, default
    the shipped network); a markdown report at ``out`` (``notes``: lines under its first paragraph) and
    the per-recording figures beside it (``.json``). Each recording's figures are also kept beside its
    result (``attribution.json``), so a rerun only attributes what is new or was evaluated again."""
    from tqdm import tqdm


    engine = make_ocr_backend(backend)
    evaluated = evaluated_runs(suite, work)
    rows = []
    for run_dir in tqdm(evaluated, desc="attributing", unit="rec", disable=not progress):
        recording = suite / run_dir.name
        if not recording.is_dir():
            continue
        row = cached_attribution(run_dir, backend)
        if row is None:
            row = attribute_recording(recording, run_dir / "read", lambda page: engine.read(page).text)
        if row is not None and row.cer_true_motion is None:
            row = replace(row, cer_true_motion=true_motion_cer(recording, run_dir, backend, model))
            (run_dir / CACHE_NAME).write_text(json.dumps({"backend": backend, **asdict(row)}), encoding="utf-8")
        if row is not None:
            rows.append(row)
    if not rows:
        raise FileNotFoundError(f"{suite}: no evaluated recording has the simulator's truth files (pose_truth.npz, page_ink.npz)")
    out.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join([
        "# Where the reading errors come from",
        "",
        f"`darkread eval attribute {suite.name}`: {len(rows)} evaluated recordings, OCR `{backend}`. Each page is read four "
        "times: as the cloud stitched it; end to end again with the head's motion known exactly (the edge given "
        "the simulator's pose: every window deblurred and every view predicted from the simulator's pose, what an exact inertial "
        "sensor would give); with the same frames placed by the simulator's true pose (perfect stitching); "
        "and with each frame replaced by its window's true ink, placed the same way (perfect frames). Frame ink "
        f"recall and precision: ink within {TOLERANCE_PX} px of the window's true ink, pooled over the frames.",
        *([""] + [f"- {note}" for note in notes] if notes else []),
        "",
        attribution_table(rows),
        "",
    ])
    out.write_text(text, encoding="utf-8")
    out.with_suffix(".json").write_text(json.dumps([asdict(r) for r in rows], indent=1), encoding="utf-8")
    return out


def attribution_section(out_dir: str | Path) -> list[str]:
    """The report's "Where the errors come from" section: ``attribution.md`` beside it (written by
    ``darkread eval attribute``), without its title; nothing when there is none."""
    return page_as_section(Path(out_dir) / ATTRIBUTION_NAME, "Where the errors come from")
