"""Synthetic reading sessions for the stitcher tests: a rendered page, a reading scanpath and the
noisy binary frames a head-mounted foveated camera would deliver.

Test data, not product code. The page moves in the sensor with a slow head drift plus tremor; the
gaze (with tracker noise) walks along the lines with forward saccades, regressions and return sweeps
(some undershooting, followed by a corrective fixation); each frame is the 100x200 window around the
noisy gaze, cut from the page, with missing strokes and speckle; some frames are dropped.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field

import cv2
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from darkread.core.frame_record import FrameRecord

PARAGRAPH = (
    "Reading in the dark is hard for cameras and easy for events. A foveated window follows the "
    "gaze along each line of text, and every small binary frame shows a few words. The stitcher "
    "places these frames onto one page, line after line, so that a text recogniser can read the "
    "whole page back. Head motion moves the page in the sensor, so the frames must be registered "
    "against what was already seen."
)


@dataclass(frozen=True)
class RenderedPage:
    mask: np.ndarray  # uint8 [H, W], 1 = ink
    coverage: np.ndarray  # float32 [H, W], ink coverage in [0, 1] (what a camera samples)
    text_lines: list[str]
    line_boxes: list[tuple[int, int, int, int]]  # (x0, y0, x1, y1) of each line's ink
    line_centres: list[tuple[int, int, float]]  # (x_start, x_end, y of the x-height centre)
    x_height_px: float
    pitch_px: int


@dataclass(frozen=True)
class ScanParams:
    """How the synthetic reader and camera behave; defaults match the task's assumptions."""

    frame_hw: tuple[int, int] = (100, 200)
    head_start_xy: tuple[float, float] = (300.0, 180.0)  # page top-left in the sensor
    drift_amplitude_px: float = 30.0  # slow head drift (sum of two slow sinusoids per axis)
    tremor_px: float = 1.0  # per-frame head jitter (std)
    roll_deg: float = 0.4  # slow head roll amplitude (the page rotates in the sensor)
    page_tilt_deg: float = 0.0  # constant rotation of the page in the sensor (page held askew)
    stroke_threshold: tuple[float, float] = (0.4, 0.6)  # per-frame binarisation level (stroke width varies)
    gaze_noise_px: float = 15.0  # per-sample gaze noise (std, per axis)
    fixation_bias_px: float = 8.0  # per-fixation systematic gaze offset (std, per axis)
    frames_per_fixation: tuple[int, int] = (2, 4)
    saccade_px: tuple[float, float] = (70.0, 15.0)  # forward saccade mean, std (7-9 letters)
    regression_prob: float = 0.12
    undershoot_prob: float = 0.35
    stroke_dropout: float = 0.12  # fraction of ink erased in blobs (missing strokes)
    speckle: float = 0.008  # fraction of pixels turned to ink
    drop_prob: float = 0.1  # frames lost on the way
    frame_dt_us: int = 40_000
    saccade_dt_us: int = 30_000


@dataclass
class Reading:
    page: RenderedPage
    frames: list[FrameRecord]
    line_of_frame: list[int]  # true line index of each delivered frame
    head_xy: list[tuple[int, int]]  # page top-left in the sensor at each delivered frame (without rotation)
    window_centres: list[tuple[float, float]]  # page coordinates of each delivered window's centre
    params: ScanParams = field(default_factory=ScanParams)


def render_page(
    text: str = PARAGRAPH, width_chars: int = 44, font_px: int = 19, margin_px: int = 140, supersample: int = 4
) -> RenderedPage:
    """Render DejaVu Sans text (x-height ~10 px) at ``supersample`` x and box-filter it down."""
    from matplotlib import font_manager

    font_path = font_manager.findfont("DejaVu Sans")
    font = ImageFont.truetype(font_path, font_px * supersample)
    lines = textwrap.wrap(text, width_chars)
    pitch = round(font_px * 1.5)
    x_height = 0.547 * font_px  # DejaVu Sans x-height / em
    ascent, _ = font.getmetrics()
    widths = [font.getlength(line) / supersample for line in lines]
    page_w = int(max(widths)) + 2 * margin_px
    page_h = pitch * len(lines) + 2 * margin_px
    big = Image.new("L", (page_w * supersample, page_h * supersample), 0)
    draw = ImageDraw.Draw(big)
    centres: list[tuple[int, int, float]] = []
    for i, (line, w) in enumerate(zip(lines, widths)):
        top = margin_px + i * pitch
        draw.text((margin_px * supersample, top * supersample), line, font=font, fill=255)
        baseline = top + ascent / supersample
        centres.append((margin_px, int(margin_px + w), baseline - x_height / 2))
    small = big.resize((page_w, page_h), Image.Resampling.BOX)
    coverage = np.asarray(small, dtype=np.float32) / 255.0
    mask = (coverage >= 0.5).astype(np.uint8)
    boxes = []
    for _x0, _x1, yc in centres:
        band = mask[int(yc - pitch / 2) : int(yc + pitch / 2)]
        rows = np.flatnonzero(band.any(axis=1))
        cols = np.flatnonzero(band.any(axis=0))
        y_base = int(yc - pitch / 2)
        boxes.append((int(cols[0]), y_base + int(rows[0]), int(cols[-1]) + 1, y_base + int(rows[-1]) + 1))
    return RenderedPage(mask, coverage, lines, boxes, centres, x_height, pitch)


def _head_track(rng: np.random.Generator, params: ScanParams):
    """Page top-left in the sensor as a function of time: slow drift + independent tremor."""
    periods = rng.uniform(4e6, 9e6, size=(2, 2))
    phases = rng.uniform(0, 2 * np.pi, size=(2, 2))
    amps = params.drift_amplitude_px * rng.uniform(0.5, 1.0, size=(2, 2))
    roll_period, roll_phase = rng.uniform(5e6, 10e6), rng.uniform(0, 2 * np.pi)

    def at(t_us: int) -> tuple[np.ndarray, float]:
        slow = (amps * np.sin(2 * np.pi * t_us / periods + phases)).sum(axis=1)
        slow -= (amps * np.sin(phases)).sum(axis=1)  # start at head_start_xy
        roll = params.roll_deg * np.sin(2 * np.pi * t_us / roll_period + roll_phase)
        return np.asarray(params.head_start_xy) + slow + rng.normal(0, params.tremor_px, 2), float(roll)

    return at


def _scanpath(rng: np.random.Generator, page: RenderedPage, params: ScanParams) -> list[tuple[float, float, int]]:
    """Fixations (x, y, line) in page coordinates, in reading order."""
    fixations: list[tuple[float, float, int]] = []
    for li, (x0, x1, yc) in enumerate(page.line_centres):
        if li > 0 and rng.random() < params.undershoot_prob:
            fixations.append((x0 + rng.uniform(90, 150), yc, li))  # undershooting return sweep
            x = x0 + rng.uniform(15, 45)  # corrective fixation
        else:
            x = x0 + rng.uniform(30, 70)
        end = x1 - rng.uniform(30, 60)
        while True:
            fixations.append((x, yc, li))
            if x >= end:
                break
            if rng.random() < params.regression_prob and x > x0 + 100:
                fixations.append((x - rng.uniform(30, 80), yc, li))
            x = min(end, x + max(30.0, rng.normal(*params.saccade_px)))
    return fixations


def _page_to_sensor(page: RenderedPage, head: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) with sensor = R @ page + t: the page turned by ``angle_deg`` about its centre, then
    moved by the head offset."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    rot = np.array([[c, -s], [s, c]])
    centre = np.array([page.mask.shape[1] / 2, page.mask.shape[0] / 2])
    return rot, centre - rot @ centre + head


def _sample_window(page: RenderedPage, origin: np.ndarray, rot: np.ndarray, shift: np.ndarray, hw: tuple[int, int]):
    """Ink coverage seen by the window whose top-left is ``origin`` in the sensor, and the page
    coordinates of its centre."""
    h, w = hw
    back = rot.T  # sensor -> page: back @ (sensor - shift)
    frame_to_page = np.hstack([back, (back @ (origin - shift))[:, None]]).astype(np.float64)
    window = cv2.warpAffine(
        page.coverage, frame_to_page, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderValue=0.0
    )
    centre = frame_to_page @ np.array([(w - 1) / 2, (h - 1) / 2, 1.0])
    return window, (float(centre[0]), float(centre[1]))


def _degrade(rng: np.random.Generator, coverage: np.ndarray, params: ScanParams) -> np.ndarray:
    """Binarise at a per-frame level (stroke width varies), then missing strokes (blob-shaped
    erasures) and speckle, as a low-light reconstruction shows them."""
    window = coverage >= rng.uniform(*params.stroke_threshold)
    noise = cv2.GaussianBlur(rng.random(window.shape).astype(np.float32), (0, 0), 2.0)
    dropout = params.stroke_dropout * rng.uniform(0.5, 1.5)
    erase = noise < np.quantile(noise, dropout)
    speckle = rng.random(window.shape) < params.speckle
    return ((window & ~erase) | speckle).astype(np.uint8)


def simulate_reading(page: RenderedPage | None = None, params: ScanParams = ScanParams(), seed: int = 0) -> Reading:
    """Frames of one reading pass over ``page`` (rendered with defaults when None)."""
    rng = np.random.default_rng(seed)
    page = page or render_page()
    h, w = params.frame_hw
    head_at = _head_track(rng, params)
    frames: list[FrameRecord] = []
    lines: list[int] = []
    heads: list[tuple[int, int]] = []
    centres: list[tuple[float, float]] = []
    t = 0
    frame_id = 0
    for fx, fy, li in _scanpath(rng, page, params):
        bias = rng.normal(0, params.fixation_bias_px, 2)
        for _ in range(int(rng.integers(params.frames_per_fixation[0], params.frames_per_fixation[1] + 1))):
            jitter = min(5000, params.frame_dt_us // 2)  # frames stay in time order
            t += params.frame_dt_us + int(rng.integers(-jitter, jitter))
            head, roll = head_at(t)
            rot, shift = _page_to_sensor(page, head, params.page_tilt_deg + roll)
            gaze = rot @ np.array([fx, fy]) + shift + bias + rng.normal(0, params.gaze_noise_px, 2)
            origin = np.round(gaze - [w / 2, h / 2]).astype(int)
            window, centre = _sample_window(page, origin, rot, shift, (h, w))
            frame_id += 1
            if rng.random() < params.drop_prob:
                continue
            frames.append(
                FrameRecord(
                    frame_id=frame_id,
                    t_us=t,
                    mask=_degrade(rng, window, params),
                    origin=(int(origin[0]), int(origin[1])),
                    gaze_px=(float(gaze[0]), float(gaze[1])),
                )
            )
            lines.append(li)
            heads.append((round(head[0]), round(head[1])))
            centres.append(centre)
        t += params.saccade_dt_us
    return Reading(page, frames, lines, heads, centres, params)


def _f1_at(padded: np.ndarray, result: np.ndarray, truth_ink: int, near: tuple[int, int] | None, reach: int):
    rh, rw = result.shape
    if near is None:
        x0, y0, region = 0, 0, padded
    else:
        x0, y0 = max(0, near[0] - reach), max(0, near[1] - reach)
        region = padded[y0 : near[1] + reach + rh, x0 : near[0] + reach + rw]
    score = cv2.matchTemplate(region, result.astype(np.float32), cv2.TM_CCORR)
    _, _, _, (bx, by) = cv2.minMaxLoc(score)
    bx, by = bx + x0, by + y0
    tp = int(np.count_nonzero((padded[by : by + rh, bx : bx + rw] > 0) & (result > 0)))
    return 2 * tp / max(1, int(np.count_nonzero(result)) + truth_ink), (bx, by)


def _tolerant_f1(padded: np.ndarray, result: np.ndarray, at: tuple[int, int], truth_ink: int, tol: int) -> float:
    """F1 where ink within ``tol`` px of the other side's ink counts as matched."""
    rh, rw = result.shape
    truth_here = (padded[at[1] : at[1] + rh, at[0] : at[0] + rw] > 0).astype(np.uint8)
    kernel = np.ones((2 * tol + 1, 2 * tol + 1), np.uint8)
    res = (result > 0).astype(np.uint8)
    precision = np.count_nonzero(res & cv2.dilate(truth_here, kernel)) / max(1, np.count_nonzero(res))
    recall = np.count_nonzero(truth_here & cv2.dilate(res, kernel)) / max(1, truth_ink)
    return 2 * precision * recall / max(1e-9, precision + recall)


def ink_f1_aligned(
    result: np.ndarray, truth: np.ndarray, max_roll_deg: float = 1.0, tolerance_px: int = 0
) -> tuple[float, tuple[int, int]]:
    """Ink F1 of ``result`` against ``truth`` at the best alignment (shift, and roll up to
    ``max_roll_deg`` in 0.1 degree steps: a head roll at the first line tilts the whole page).

    Exact: F1 = 2 TP / (|result ink| + |truth ink|), so ink the result lacks anywhere on the page
    counts. With ``tolerance_px`` > 0, ink within that distance of the other side's ink matches
    (strokes are ~2 px wide, so a 1 px offset otherwise costs half the stroke).
    Returns (F1, (dx, dy)) with (dx, dy) the position of the result's top-left in the truth.
    """
    rh, rw = result.shape
    padded = np.pad(truth.astype(np.float32), ((rh, rh), (rw, rw)))
    truth_ink = int(np.count_nonzero(truth))
    best, where = _f1_at(padded, result, truth_ink, None, 0)
    pose = (result, where)
    for angle in np.arange(-max_roll_deg, max_roll_deg + 1e-9, 0.1):
        rot = cv2.getRotationMatrix2D((rw / 2, rh / 2), float(angle), 1.0)
        turned = (cv2.warpAffine(result.astype(np.float32), rot, (rw, rh), flags=cv2.INTER_LINEAR) >= 0.5).astype(
            np.uint8
        )
        f1, at = _f1_at(padded, turned, truth_ink, where, 12)
        if f1 > best:
            best, pose = f1, (turned, at)
    if tolerance_px > 0:
        best = _tolerant_f1(padded, pose[0], pose[1], truth_ink, tolerance_px)
    return best, (where[0] - rw, where[1] - rh)
