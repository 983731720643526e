"""Where a page's reading errors come from: the network's frames, the stitcher's placement, or the OCR.

For a synthetic recording the simulator wrote down the page's true pose (``pose_truth.npz``) and its
ink (``page_ink.npz``). Beside the page the cloud stitched from the frames a ``darkread read`` stored,
two more pages are read by the same OCR, both on the page's own raster:

* ``placed``: the same frames, each placed where the true pose puts it (perfect stitching);
* ``ideal``: the true ink of each frame's window, placed the same way (perfect frames and stitching).

``stitched`` close to ``placed`` means the stitcher is not what fails; ``placed`` far above
``ideal`` means the frames are. Each frame is also scored against its window's true ink (recall: the
share of true ink with a predicted pixel within 1 px; precision: the converse), which tells missing
strokes from spurious ones. Frames are matched to the pose at their ``t_us``.
"""

from __future__ import annotations

import asyncio
import json
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

ATTRIBUTION_NAME = "attribution.md"
CACHE_NAME = "attribution.json"  # per recording, beside its result.json: a rerun (or a larger suite) reuses it
TOLERANCE_PX = 1  # ink within this many pixels counts as found (strokes are ~2 px wide)
PAGE_GAIN = 2.0  # placed pages: mean ink share x this, clipped (a stroke seen in half the frames is black)


@dataclass(frozen=True)
class PageTruth:
    """What the simulator knows of a recording: the page ink raster, its scale and the pose over time."""

    ink: np.ndarray  # float32 coverage 0..1, page raster
    px_per_mm: float
    pose_at: Callable[[float], np.ndarray]  # t_us -> page mm -> normalised-camera homography
    calibration: Any


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


def load_truth(recording: Path) -> PageTruth | None:
    """The recording's truth files, or None when it has none (a real recording)."""
    from darkread.edge.io.calibration import load_calibration
    from darkread.models.train.annotate import load_pose_truth

    ink_path = recording / "page_ink.npz"
    pose = load_pose_truth(recording)
    if pose is None or not ink_path.is_file():
        return None
    with np.load(ink_path) as z:
        ink, px_per_mm = z["ink"].astype(np.float32), float(z["px_per_mm"])
    return PageTruth(ink, px_per_mm, pose.at, load_calibration(recording / "calibration.json"))


def stored_frames(cloud_dir: Path) -> list[Any]:
    """Every frame of the one session a ``darkread read`` stored in ``cloud_dir`` (SQLite), in order."""
    from darkread.cloud.store.sqlite import SqliteStore

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


def _window_box(truth: PageTruth, origin: tuple[int, int], shape: tuple[int, int], H: np.ndarray) -> tuple[int, int, int, int] | None:
    """The part of the page raster (row0, row1, col0, col1) a window can see under ``H`` (its corners'
    rays on the page, 2 texels of margin); None when it sees none of it."""
    from darkread.models.train.annotate import page_coordinates, window_rays

    rays = window_rays(truth.calibration, origin, shape)
    h, w = shape
    corners = rays[[0, w - 1, (h - 1) * w, h * w - 1]]
    px = page_coordinates(H, corners) * truth.px_per_mm
    rows, cols = truth.ink.shape
    c0, r0 = np.floor(px.min(axis=0)).astype(int) - 2
    c1, r1 = np.ceil(px.max(axis=0)).astype(int) + 2
    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, rows), min(c1, cols)
    return (r0, r1, c0, c1) if r1 > r0 and c1 > c0 else None


def place_frames(masks: Sequence[np.ndarray], origins: Sequence[tuple[int, int]], times_us: Sequence[float],
                 truth: PageTruth) -> np.ndarray:
    """Frames averaged on the page raster where the true pose puts them: uint8, black ink on white."""
    from darkread.models.train.annotate import project_page

    total = np.zeros(truth.ink.shape, np.float32)
    seen = np.zeros(truth.ink.shape, np.float32)
    for mask, (x0, y0), t_us in zip(masks, origins, times_us, strict=True):
        H = truth.pose_at(float(t_us))
        box = _window_box(truth, (x0, y0), mask.shape, H)
        if box is None:
            continue
        r0, r1, c0, c1 = box
        gy, gx = np.mgrid[r0:r1, c0:c1].astype(np.float64)
        points = np.c_[(gx.ravel() + 0.5) / truth.px_per_mm, (gy.ravel() + 0.5) / truth.px_per_mm]
        uv = project_page(H, truth.calibration, points).reshape(r1 - r0, c1 - c0, 2)
        mx = (uv[..., 0] - x0).astype(np.float32)
        my = (uv[..., 1] - y0).astype(np.float32)
        inside = (mx >= 0) & (mx <= mask.shape[1] - 1) & (my >= 0) & (my <= mask.shape[0] - 1)
        total[r0:r1, c0:c1] += cv2.remap(mask.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderValue=0.0) * inside
        seen[r0:r1, c0:c1] += inside
    share = np.where(seen > 0, total / np.maximum(seen, 1.0), 0.0)
    return (255.0 * (1.0 - np.clip(share * PAGE_GAIN, 0.0, 1.0))).astype(np.uint8)


def window_truth(truth: PageTruth, origin: tuple[int, int], shape: tuple[int, int], t_us: float) -> np.ndarray:
    """The true binary ink of a window (uint8, 1 = ink), as the training targets define it."""
    from darkread.models.train.annotate import render_target, window_rays

    rays = window_rays(truth.calibration, origin, shape)
    return render_target(truth.ink, truth.px_per_mm, truth.pose_at(float(t_us)), rays, shape)


def ink_found(predicted: np.ndarray, target: np.ndarray, tolerance_px: int = TOLERANCE_PX) -> tuple[int, int, int, int]:
    """(true ink found, true ink, predicted ink near true ink, predicted ink), within ``tolerance_px``."""
    kernel = np.ones((2 * tolerance_px + 1, 2 * tolerance_px + 1), np.uint8)
    pred, true = predicted.astype(np.uint8), target.astype(np.uint8)
    near_pred, near_true = cv2.dilate(pred, kernel), cv2.dilate(true, kernel)
    return (int((true & near_pred).sum()), int(true.sum()), int((pred & near_true).sum()), int(pred.sum()))


def attribute_recording(recording: Path, read_dir: Path, read_page: Callable[[np.ndarray], str]) -> Attribution | None:
    """The three readings and the frame scores of one evaluated recording (None without truth files)."""
    from darkread.eval.error_rates import error_rates
    from darkread.eval.runner import RESULT_NAME

    truth = load_truth(recording)
    if truth is None:
        return None
    result = json.loads((read_dir.parent / RESULT_NAME).read_text(encoding="utf-8"))
    frames = stored_frames(read_dir / "cloud")
    masks = [f.mask for f in frames]
    origins = [(int(f.origin[0]), int(f.origin[1])) for f in frames]
    times = [float(f.t_us) for f in frames]
    ideal = [window_truth(truth, o, m.shape, t) for m, o, t in zip(masks, origins, times, strict=True)]
    counts = np.array([ink_found(m, i) for m, i in zip(masks, ideal, strict=True)] or [[0, 0, 0, 0]], np.int64).sum(axis=0)
    reference = (recording / "text.txt").read_text(encoding="utf-8")

    def cer(page: np.ndarray) -> float:
        return min(1.0, error_rates(reference, read_page(page)).cer)

    return Attribution(
        name=recording.name, lux=float(result["lux"]), motion=str(result["motion"]), frames=len(frames),
        cer_stitched=min(1.0, float(result["darkread"].get("cer", 1.0))),
        cer_placed=cer(place_frames(masks, origins, times, truth)),
        cer_ideal=cer(place_frames(ideal, origins, times, truth)),
        frame_recall=float(counts[0] / max(1, counts[1])), frame_precision=float(counts[2] / max(1, counts[3])),
    )


def attribution_table(rows: Sequence[Attribution]) -> str:
    """Mean figures per lux and motion (markdown)."""
    groups: dict[tuple[float, str], list[Attribution]] = defaultdict(list)
    for row in rows:
        groups[(row.lux, row.motion)].append(row)
        groups[(row.lux, "all")].append(row)
    order = {"still": 0, "normal": 1, "walking": 2, "all": 3}
    lines = [
        "| lux | motion | n | CER stitched | CER frames placed by the true pose | CER true ink placed so | frame ink recall | frame ink precision |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for (lux, motion), members in sorted(groups.items(), key=lambda kv: (-kv[0][0], order.get(kv[0][1], 9))):
        def mean(key: str) -> float:
            return float(np.mean([getattr(m, key) for m in members]))

        label = f"**{motion}**" if motion == "all" else motion
        lines.append(f"| {lux:g} | {label} | {len(members)} | {100 * mean('cer_stitched'):.1f}% | {100 * mean('cer_placed'):.1f}% | "
                     f"{100 * mean('cer_ideal'):.1f}% | {100 * mean('frame_recall'):.0f}% | {100 * mean('frame_precision'):.0f}% |")
    return "\n".join(lines)


def cached_attribution(run_dir: Path, backend: str) -> Attribution | None:
    """The attribution stored beside a recording's result, if it is of that result and engine."""
    from darkread.eval.runner import RESULT_NAME

    cache, result = run_dir / CACHE_NAME, run_dir / RESULT_NAME
    if not cache.is_file() or (result.is_file() and result.stat().st_mtime_ns > cache.stat().st_mtime_ns):
        return None
    stored = json.loads(cache.read_text(encoding="utf-8"))
    if stored.pop("backend", None) != backend:
        return None
    return Attribution(**stored)


def write_attribution(suite: Path, work: Path, out: Path, *, backend: str = "local", progress: bool = True,
                      notes: Sequence[str] = ()) -> Path:
    """Attribute every evaluated recording of ``suite`` (results in ``work``); a markdown report at ``out``
    (``notes``: lines under its first paragraph) and the per-recording figures beside it (``.json``).
    Each recording's figures are also kept beside its result (``attribution.json``), so a rerun only
    attributes what is new or was evaluated again."""
    from tqdm import tqdm

    from darkread.eval.runner import make_ocr_backend

    engine = make_ocr_backend(backend)
    evaluated = sorted(p for p in work.iterdir() if (p / "read" / "cloud").is_dir()) if work.is_dir() else []
    if not evaluated:
        raise FileNotFoundError(f"{work}: no evaluated recordings; run `darkread eval {suite} --work {work}` first")
    rows = []
    for run_dir in tqdm(evaluated, desc="attributing", unit="rec", disable=not progress):
        recording = suite / run_dir.name
        if not recording.is_dir():
            continue
        row = cached_attribution(run_dir, backend)
        if row is None:
            row = attribute_recording(recording, run_dir / "read", lambda page: engine.read(page).text)
            if row is not None:
                (run_dir / CACHE_NAME).write_text(json.dumps({"backend": backend, **asdict(row)}), encoding="utf-8")
        if row is not None:
            rows.append(row)
    if not rows:
        raise FileNotFoundError(f"{suite}: no evaluated recording has the simulator's truth files (pose_truth.npz, page_ink.npz)")
    out.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join([
        "# Where the reading errors come from",
        "",
        f"`darkread eval attribute {suite.name}`: {len(rows)} evaluated recordings, OCR `{backend}`. Each page is read three "
        "times: as the cloud stitched it; with the same frames placed by the simulator's true pose (perfect stitching); "
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
    path = Path(out_dir) / ATTRIBUTION_NAME
    if not path.is_file():
        return []
    body = path.read_text(encoding="utf-8").splitlines()
    body = body[1:] if body and body[0].startswith("# ") else body
    return ["## Where the errors come from", *body, ""]
