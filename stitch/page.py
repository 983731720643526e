"""Lines onto the page: weighted composition of the line strips, line boxes, final threshold."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.stitch.canvas import Canvas
from darkread.stitch.config import StitchConfig
from darkread.stitch.stitched_page import StitchedPage
from darkread.stitch.strip import LineStrip

_MIN_DEN = 1e-6


class PageCanvas:
    """Finished lines: sum of weight x ink and of weight, so any strip can be added or composed."""

    def __init__(self) -> None:
        self.canvas = Canvas(("num", "den", "views"))

    def fork(self) -> PageCanvas:
        twin = PageCanvas()
        twin.canvas = self.canvas.fork()
        return twin

    def add_strip(self, strip: LineStrip) -> None:
        if strip.canvas.empty:
            return
        x0, y0, x1, y1 = strip.canvas.box
        self.canvas.ensure(x0, y0, x1, y1)
        weight = strip.weight()
        self.canvas.view("num", x0, y0, x1, y1)[...] += weight * strip.canvas.layers["avg"]
        self.canvas.view("den", x0, y0, x1, y1)[...] += weight
        self.canvas.view("views", x0, y0, x1, y1)[...] += strip.canvas.layers["count"]

    def views(self, strip: LineStrip | None, box: tuple[int, int, int, int]) -> np.ndarray:
        """How many frames saw each pixel of ``box`` (finished lines plus ``strip``)."""
        views = self.canvas.crop("views", *box)
        if strip is not None and not strip.canvas.empty:
            views += strip.canvas.crop("count", *box)
        return views

    def reference(self, strip: LineStrip | None, box: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Ink probability and 'seen' mask in ``box`` from the finished lines plus ``strip``."""
        num, den = self.canvas.crop("num", *box), self.canvas.crop("den", *box)
        if strip is not None and not strip.canvas.empty:
            weight = strip.canvas.crop("conf", *box) ** 2
            num += weight * strip.canvas.crop("avg", *box)
            den += weight
        seen = den > _MIN_DEN
        return np.where(seen, num / np.maximum(den, _MIN_DEN), 0.0).astype(np.float32), seen


def union_box(boxes: Sequence[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    return min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes)


def ink_level(avg: np.ndarray, cfg: StitchConfig, views: np.ndarray | None = None) -> float:
    """The page's full ink: the ``grey_saturation`` probability, or less on a page whose frames
    never agree that much (dim light: each frame finds a different 40-60 % of the strokes, and
    their average stays grey). The ``ink_percentile``-th percentile of the probability where it
    is above ``faint_ink``, bounded by ``min_ink_level`` (a page of noise is not stretched to ink)."""
    seen = avg > cfg.faint_ink
    if views is not None:
        seen &= views >= cfg.min_views
    if not seen.any():
        return cfg.grey_saturation
    level = float(np.percentile(avg[seen], cfg.ink_percentile))
    return float(np.clip(level, cfg.min_ink_level, cfg.grey_saturation))


def binarize(avg: np.ndarray, cfg: StitchConfig, views: np.ndarray | None = None, level: float | None = None) -> np.ndarray:
    """Threshold the alpha-averaged ink probability at ``ink_threshold`` of the page's full ink
    (``level``, default ``grey_saturation``: the threshold as configured); drop specks below
    ``min_component_px`` and, given ``views``, ink that fewer than ``min_views`` frames saw (one
    noisy frame is no evidence)."""
    scale = 1.0 if level is None else level / cfg.grey_saturation
    ink = (avg > cfg.ink_threshold * scale).astype(np.uint8)
    if views is not None and cfg.min_views > 1:
        ink[views < cfg.min_views] = 0
    if cfg.min_component_px > 1 and ink.any():
        _, labels, stats, _ = cv2.connectedComponentsWithStats(ink, connectivity=8)
        small = stats[:, cv2.CC_STAT_AREA] < cfg.min_component_px
        small[0] = False
        if small.any():
            ink[small[labels]] = 0
    return ink


def covered_box(seen: np.ndarray) -> tuple[int, int, int, int] | None:
    rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
    if rows.size == 0:
        return None
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def rotation_to_fit(shape: tuple[int, int], angle_deg: float) -> tuple[np.ndarray, tuple[int, int]]:
    """2x3 rotation of an image about its centre onto a canvas that holds all of it, and that
    canvas's (width, height)."""
    h, w = shape
    turn = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), float(angle_deg), 1.0)
    corners = np.array([[0, 0, 1], [w, 0, 1], [0, h, 1], [w, h, 1]], dtype=np.float64) @ turn.T
    low, high = corners.min(axis=0), corners.max(axis=0)
    turn[:, 2] -= low
    size = np.ceil(high - low).astype(int)
    return turn, (int(size[0]), int(size[1]))


def estimate_skew(ink: np.ndarray, max_deg: float, step_deg: float = 0.5) -> float:
    """Rotation (degrees, ``cv2.getRotationMatrix2D`` sense) that makes the text lines horizontal:
    the one whose row profile is sharpest (largest variance), coarse then fine. 0 when off."""
    if max_deg <= 0 or not ink.any():
        return 0.0
    small = cv2.resize(ink.astype(np.float32), None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)

    def sharpness(angle: float) -> float:
        turn, size = rotation_to_fit(small.shape, angle)
        return float(cv2.warpAffine(small, turn, size, flags=cv2.INTER_LINEAR).sum(axis=1).var())

    coarse = np.arange(-max_deg, max_deg + 1e-9, step_deg)
    best = float(coarse[int(np.argmax([sharpness(a) for a in coarse]))])
    fine = np.arange(best - step_deg, best + step_deg + 1e-9, 0.1)
    return float(fine[int(np.argmax([sharpness(a) for a in fine]))])


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def text_bands(ink: np.ndarray) -> list[tuple[int, int, float]]:
    """Text lines of an ink mask as row bands (top, bottom, centre), top to bottom.

    A line's core is a run of rows whose smoothed ink profile is well above the page's typical
    line (the x-height band); it extends up and down (ascenders, descenders) to the profile
    valleys that separate it from its neighbours. Short lines (a paragraph's last words) are found
    in a second pass among the rows left over, with a lower floor.
    """
    h = ink.shape[0]
    profile = ink.sum(axis=1).astype(np.float32)
    if profile.max(initial=0) <= 0:
        return []
    smooth = np.convolve(profile, np.ones(5, np.float32) / 5, mode="same")
    typical = float(np.percentile(smooth[smooth > 0], 90))
    taken = np.zeros(h, bool)
    bands = []
    for floor, min_rows in ((0.3 * typical, 1), (0.05 * typical, 4)):
        core = (smooth >= floor) & ~taken
        for c0, c1 in _runs(core):
            if c1 - c0 < min_rows:
                continue
            top, bottom = c0, c1 - 1
            while (
                top > 0
                and not taken[top - 1]
                and profile[top - 1] > 0
                and smooth[top - 1] <= smooth[top]
                and not core[top - 1]
            ):
                top -= 1
            while (
                bottom < h - 1
                and not taken[bottom + 1]
                and profile[bottom + 1] > 0
                and smooth[bottom + 1] <= smooth[bottom]
                and not core[bottom + 1]
            ):
                bottom += 1
            taken[top : bottom + 1] = True
            centre = float(np.average(np.arange(c0, c1), weights=profile[c0:c1] + 1e-6))
            bands.append((top, bottom + 1, centre))
    return sorted(bands, key=lambda band: band[2])


def main_column_span(columns_with_ink: np.ndarray, max_gap: int) -> tuple[int, int] | None:
    """Longest run of ink columns whose gaps stay below ``max_gap`` (word gaps are a few px)."""
    cols = np.flatnonzero(columns_with_ink)
    if cols.size == 0:
        return None
    cuts = np.flatnonzero(np.diff(cols) > max_gap)
    starts = np.concatenate([[0], cuts + 1])
    ends = np.concatenate([cuts, [cols.size - 1]])
    best = int(np.argmax(cols[ends] - cols[starts]))
    return int(cols[starts[best]]), int(cols[ends[best]]) + 1


def assign_lines(gaze_rows: Sequence[float], band_centres: Sequence[float]) -> list[int]:
    """Band index of each read line (in reading order), from its mean gaze row.

    The gaze tracker's common vertical bias (calibration) is estimated first as the median offset
    to the nearest band and removed. Lines read one after another go down the page, so the
    assignment is the monotone one (each line on a band below the one before while there are
    bands enough) of least squared distance, which rides over single lines whose gaze sat nearer
    to a neighbour: a return sweep goes down one line, and staying on a band (a line split in two
    by a long regression) or skipping one costs as much as a gaze error of one pitch. A line read
    well above the previous one (back up the page) restarts the order.
    """
    if not band_centres:
        return [-1] * len(gaze_rows)
    if not gaze_rows:
        return []
    centres = np.asarray(band_centres, dtype=np.float64)
    rows = np.asarray(gaze_rows, dtype=np.float64)
    nearest = np.abs(rows[:, None] - centres[None, :]).argmin(axis=1)
    rows = rows + float(np.median(centres[nearest] - rows))
    pitch = _median_pitch(centres)
    out: list[int] = []
    start = 0
    for i in range(1, len(rows) + 1):
        if i == len(rows) or rows[i] < rows[i - 1] - 1.5 * pitch:
            out += _monotone_assignment(rows[start:i], centres, pitch**2)
            start = i
    return out


def _median_pitch(centres: np.ndarray) -> float:
    return float(np.median(np.diff(centres))) if centres.size > 1 else 0.0


def _monotone_assignment(rows: np.ndarray, centres: np.ndarray, jump_cost: float) -> list[int]:
    """Non-decreasing band indices for ``rows`` minimising squared distance plus transition costs
    (dynamic programme): the next band is free (a return sweep goes down one line), staying costs
    ``jump_cost`` and every band skipped costs ``jump_cost`` too."""
    cost = (rows[:, None] - centres[None, :]) ** 2
    n, m = cost.shape
    steps = np.arange(m)[None, :] - np.arange(m)[:, None]  # [from, to]
    transition = np.where(steps < 0, np.inf, np.where(steps == 1, 0.0, jump_cost * np.abs(steps - 1)))
    total = cost[0].copy()
    choice = np.zeros((n, m), dtype=np.int64)
    for i in range(1, n):
        via = total[:, None] + transition  # [from, to]
        choice[i] = via.argmin(axis=0)
        total = cost[i] + via.min(axis=0)
    path = [int(np.argmin(total))]
    for i in range(n - 1, 0, -1):
        path.append(int(choice[i][path[-1]]))
    return path[::-1]


def naive_page(frames: Sequence[FrameRecord], average: bool = False, cfg: StitchConfig = StitchConfig()) -> StitchedPage:
    """Reference without registration: every frame pasted at its sensor position (``origin``),
    later frames over earlier ones; with ``average``, averaged and thresholded instead."""
    canvas = Canvas(("sum", "count"))
    for f in frames:
        x, y = f.origin
        h, w = f.mask.shape
        canvas.ensure(x, y, x + w, y + h)
        if average:
            canvas.view("sum", x, y, x + w, y + h)[...] += f.mask
        else:
            canvas.view("sum", x, y, x + w, y + h)[...] = f.mask
        canvas.view("count", x, y, x + w, y + h)[...] += 1
    if canvas.empty:
        return StitchedPage(np.zeros((0, 0), np.uint8), [], [], 0, 0)
    count = canvas.layers["count"]
    x0, y0, x1, y1 = covered_box(count > 0) or (0, 0, 0, 0)
    if average:
        avg = np.where(count > 0, canvas.layers["sum"] / np.maximum(count, 1), 0)
        image = binarize(avg[y0:y1, x0:x1], cfg)
    else:
        image = (canvas.layers["sum"][y0:y1, x0:x1] > 0).astype(np.uint8)
    return StitchedPage(image, [], [], len(frames), 0)
