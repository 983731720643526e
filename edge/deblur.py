"""A window's events moved to where the page was at its newest event, so head motion does not smear the strokes.

In dim light a window's 1600 events span 20-50 ms, and a moving head slides the page 4-10 px in
that time: every stroke is smeared over that length, and the network (trained on windows of every
speed) finds a third fewer of them. The motion is measured from the events themselves, by contrast
maximisation: moved back along the right motion, the events of one edge pile up on one line, and
the image of counts is sharpest. The motion is taken as steady over the window's span (one
displacement, from its first event to its newest), and searched on a dense grid: the events are
split by time into ``slices`` count images, and the sharpness of the warped image is the sum of
their pairwise correlations at the shifts the displacement gives them, which one FFT per slice
and pair gives for every displacement at once. Events around the window (``margin_px``) vote too.

Measured against the simulator's true pose (ink F1 of the network's frames, 10 lux): normal head
motion 0.657 -> 0.688, walking 0.597 -> 0.677 (0.743 and 0.730 with the true motion); 30 lux
walking 0.785 -> 0.819; still pages and bright light unchanged (docs/deblur.md).
Pure: numpy, OpenCV and the compiled counting of ``edge.binning``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from darkread.edge.binning import cell_tables, slice_counts, voters
from darkread.edge.events import Events
from darkread.edge.head_motion import SmearPrior
from darkread.edge.scene_motion import gaussian_transfer


@dataclass(frozen=True)
class DeblurConfig:
    enabled: bool = True
    margin_px: int = 60  # events this far around the window vote for its motion (more edges, a surer peak)
    max_shift_px: int = 16  # the page moves at most this far during one window (walking, 5 lux: ~10 px) ...
    max_speed_px_s: float = 1000.0  # ... and at most this fast (a walking head's bounce peaks near it): on a
    # short window a far peak is the text's own period (letters, lines), not motion
    step_px: float = 0.25  # the displacement grid (after a search at whole pixels)
    slices: int = 3  # count images by time; their pairwise correlations give the sharpness
    blur_px: float = 1.5  # Gaussian blur of the count images (sparse events in the dark: a smoother peak)
    min_span_us: int = 3000  # a shorter window (bright light) smears under a pixel: left as it is
    min_events: int = 200  # fewer events in the region: no motion worth measuring
    min_smear_px: float = 1.5  # a smaller smear is left as it is (moving events by a fraction only re-rounds them)
    min_gain: float = 1.015  # ... and so is one that sharpens the events by less than this factor
    bin_px: int = 2  # events counted in cells this wide

    def __post_init__(self) -> None:
        if self.margin_px < 0 or self.max_shift_px < 1 or not self.step_px > 0 or self.slices < 2 or self.blur_px < 0 or self.bin_px < 1:
            raise ValueError(f"DeblurConfig: margin >= 0, max shift >= 1, step > 0, slices >= 2, blur >= 0, bin >= 1 expected: {self}")


def region_of(origin: tuple[int, int], shape_hw: tuple[int, int], sensor_wh: tuple[int, int], margin_px: int) -> tuple[int, int, int, int]:
    """(x0, y0, width, height) of the window grown by ``margin_px``, within the sensor."""
    x0, y0 = max(origin[0] - margin_px, 0), max(origin[1] - margin_px, 0)
    x1 = min(origin[0] + shape_hw[1] + margin_px, sensor_wh[0])
    y1 = min(origin[1] + shape_hw[0] + margin_px, sensor_wh[1])
    return x0, y0, max(x1 - x0, 1), max(y1 - y0, 1)


def estimate_smear(events: Events, region: tuple[int, int, int, int], t_ref_us: int, span_us: float,
                   cfg: DeblurConfig = DeblurConfig()) -> tuple[float, float]:
    """The page's displacement (px, x right, y down) over the ``span_us`` before ``t_ref_us``, from
    ``events`` of that time in ``region`` (x0, y0, width, height); (0, 0) with too few events."""
    return smear_of(events["x"], events["y"], events["t"], region, t_ref_us, span_us, cfg)  # (the region's events vote)


def smear_of(x: np.ndarray, y: np.ndarray, t: np.ndarray, region: tuple[int, int, int, int], t_ref_us: int, span_us: float,
             cfg: DeblurConfig = DeblurConfig(), t_first_us: int | None = None) -> tuple[float, float]:
    """``estimate_smear`` of events given as their coordinates and times: the fields of a
    caller's events, not a copy of its records. Those inside ``region`` vote; with ``t_first_us``
    only those of [``t_first_us``, ``t_ref_us``]."""
    if span_us <= 0:
        return 0.0, 0.0
    t_first, t_last, n, earliest = _voting(x, y, t, region, t_ref_us, t_first_us)
    if n < cfg.min_events:
        return 0.0, 0.0
    r = int(min(max(math.ceil(cfg.max_speed_px_s * span_us / 1e6), 1), cfg.max_shift_px))
    pairs = _slice_pairs(x, y, t, region, t_ref_us, span_us, cfg, t_first, t_last, earliest, r)
    if not pairs:
        return 0.0, 0.0
    # a coarse search (linear interpolation: cheap, but it pulls peaks onto whole cells), then a
    # fine one around its best (cubic: no such pull)
    dx, dy = _displacements(float(r), 1.0)
    best, _ = _best(pairs, dx, dy, cv2.INTER_LINEAR)
    dx, dy = _displacements(1.0, cfg.step_px)
    found, top = _best(pairs, dx + np.float32(best[0]), dy + np.float32(best[1]), cv2.INTER_CUBIC)
    if max(abs(found[0]), abs(found[1])) >= r:
        return 0.0, 0.0  # the best lies at the edge of what was searched: no peak inside it
    _, still = _best(pairs, *_displacements(0.0, 1.0), cv2.INTER_CUBIC)
    # a peak barely above the still page's is noise (on still pages the best is 0.1-2 % above it;
    # a smear the network suffers from is 2-12 %)
    return found if top >= cfg.min_gain * still else (0.0, 0.0)


def smear_near(x: np.ndarray, y: np.ndarray, t: np.ndarray, region: tuple[int, int, int, int], t_ref_us: int, span_us: float,
               prior: tuple[float, float], radius_px: float, cfg: DeblurConfig = DeblurConfig(),
               t_first_us: int | None = None) -> tuple[float, float]:
    """``smear_of`` searched only within ``radius_px`` of a predicted smear ``prior`` (the gyroscope's,
    ``edge.imu_motion``): no coarse search, the motion is known to be near it. A peak the events do
    not prefer by ``min_gain`` over the prediction itself is noise (in dim light a peak a fraction
    above it is always found), so the prediction stands, as a still page does for ``smear_of``; with
    too few events to sharpen, the prediction too."""
    if span_us <= 0:
        return 0.0, 0.0
    t_first, t_last, n, earliest = _voting(x, y, t, region, t_ref_us, t_first_us)
    r = int(math.ceil(max(abs(prior[0]), abs(prior[1])) + radius_px + 1))
    if n < cfg.min_events or r > 4 * cfg.max_shift_px:
        return prior
    pairs = _slice_pairs(x, y, t, region, t_ref_us, span_us, cfg, t_first, t_last, earliest, r)
    if not pairs:
        return prior
    dx, dy = _displacements(float(radius_px), cfg.step_px)
    found, top = _best(pairs, dx + np.float32(prior[0]), dy + np.float32(prior[1]), cv2.INTER_CUBIC)
    _, at_prior = _best(pairs, np.full((1, 1), prior[0], np.float32), np.full((1, 1), prior[1], np.float32), cv2.INTER_CUBIC)
    return found if top >= cfg.min_gain * at_prior else prior


def _voting(x: np.ndarray, y: np.ndarray, t: np.ndarray, region: tuple[int, int, int, int], t_ref_us: int,
            t_first_us: int | None) -> tuple[int, int, int, int]:
    """(first, last time that vote, how many events of ``region`` do, the earliest of them): every
    time without ``t_first_us``, else [``t_first_us``, ``t_ref_us``]."""
    clock = np.iinfo(np.int64)
    t_first, t_last = (int(clock.min), int(clock.max)) if t_first_us is None else (int(t_first_us), int(t_ref_us))
    x0, y0, width, height = region
    n, earliest = voters(x, y, t, x0, y0, width, height, t_first, t_last)
    return t_first, t_last, n, earliest


def _slice_pairs(x: np.ndarray, y: np.ndarray, t: np.ndarray, region: tuple[int, int, int, int], t_ref_us: int,
                 span_us: float, cfg: DeblurConfig, t_first: int, t_last: int, earliest: int,
                 r: int) -> list[tuple[np.ndarray, np.float32]]:
    """The region's events in ``cfg.slices`` count images by age, and the correlation of each pair of
    them with the lag (cells) between their mean ages; room for shifts up to ``r`` px."""
    x0, y0, width, height = region
    k_n = cfg.slices
    oldest = (t_ref_us - float(earliest)) / span_us  # 0 at the reference, 1 a span before
    if not oldest > 0:
        return []
    b = cfg.bin_px  # counted in b x b cells: a quarter of the transforms, the peak still found to a fraction of a cell
    pad = -(-r // b) + 1
    shape = (cv2.getOptimalDFTSize(-(-height // b) + 2 * pad), cv2.getOptimalDFTSize(-(-width // b) + 2 * pad))
    flat_images = np.zeros((k_n, shape[0] * shape[1]), np.float32)
    counts, age_sums = np.zeros(k_n, np.int64), np.zeros(k_n, np.float64)
    # (by age, each event in one of k_n slices; counted in one compiled pass: edge.binning)
    column_of, row_of = cell_tables(width, height, b, pad, row_stride=shape[1])
    slice_counts(x, y, t, x0, y0, column_of, row_of, t_first, t_last, int(t_ref_us), float(span_us), oldest, flat_images, counts, age_sums)
    images = flat_images.reshape(k_n, *shape)
    mean_age = age_sums / np.maximum(counts, 1)
    spectra = [cv2.dft(image) for image in images]  # (real, packed)
    if cfg.blur_px > 0:  # each image blurred, in the spectrum (a product there, not a pass over the image)
        transfer = _blur_transfer(shape, cfg.blur_px / b)
        spectra = [cv2.mulSpectrums(spectrum, transfer, 0) for spectrum in spectra]
    pairs = []  # (correlation, lag in cells) of each pair of slices
    for i in range(k_n):
        for j in range(i + 1, k_n):
            if counts[i] and counts[j]:
                # correlation[s] = sum_y image_i(y) image_j(y + s): their overlap when j sits s further on
                correlation = cv2.idft(cv2.mulSpectrums(spectra[j], spectra[i], 0, conjB=True), flags=cv2.DFT_REAL_OUTPUT | cv2.DFT_SCALE)
                pairs.append((correlation, np.float32((mean_age[i] - mean_age[j]) / b)))
    return pairs


def _best(pairs: list[tuple[np.ndarray, np.float32]], dx: np.ndarray, dy: np.ndarray, interpolation: int) -> tuple[tuple[float, float], float]:
    """The displacement of the grid (``dx``, ``dy``) under which the slices overlap most, and that overlap."""
    sharpness = np.zeros(dx.shape, np.float32)
    for correlation, lag in pairs:
        # (at fractional shifts, circularly: a negative shift wraps to the far end)
        sharpness += cv2.remap(correlation, dx * lag, dy * lag, interpolation, borderMode=cv2.BORDER_WRAP)
    k = int(sharpness.argmax())  # (a flat index: np.unravel_index costs more than the argmax)
    return (float(dx.flat[k]), float(dy.flat[k])), float(sharpness.flat[k])


@lru_cache(maxsize=64)  # (a few sizes of count images come back every window)
def _blur_transfer(shape: tuple[int, int], sigma: float) -> np.ndarray:
    """The spectrum of a circular Gaussian blur of ``sigma`` cells over images of ``shape`` (read-only)."""
    transfer = gaussian_transfer(shape, sigma)
    transfer.flags.writeable = False
    return transfer


@lru_cache(maxsize=64)  # (one coarse grid per search radius, and the fine one)
def _displacements(max_shift_px: float, step_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The displacement grid searched (x and y, float32 [n, n])."""
    grid = np.arange(-max_shift_px, max_shift_px + 1e-9, step_px, dtype=np.float32)
    dx, dy = np.meshgrid(grid, grid)
    return dx, dy


def deblur(window: Events, smear: tuple[float, float], t_ref_us: int, span_us: float, origin: tuple[int, int],
           shape_hw: tuple[int, int]) -> Events:
    """``window``'s events moved along ``smear`` (the page's displacement over ``span_us`` before
    ``t_ref_us``) to where the page was at ``t_ref_us``; those that leave the window are dropped."""
    if smear == (0.0, 0.0) or window.shape[0] == 0 or span_us <= 0:
        return window
    ahead = (t_ref_us - window["t"].astype(np.float64)) / span_us
    return moved_to(window, window["x"] + smear[0] * ahead, window["y"] + smear[1] * ahead, origin, shape_hw)


def moved_to(window: Events, x: np.ndarray, y: np.ndarray, origin: tuple[int, int], shape_hw: tuple[int, int]) -> Events:
    """A copy of ``window`` with its events at the pixels nearest to ``x``, ``y`` (sensor px, one per
    event); those that land outside the window at ``origin`` (``shape_hw``) or nowhere (NaN) are dropped."""
    x, y = np.rint(x), np.rint(y)
    keep = (x >= origin[0]) & (x < origin[0] + shape_hw[1]) & (y >= origin[1]) & (y < origin[1] + shape_hw[0])
    moved = window[keep]  # (a copy: the caller's events stay as they were)
    moved["x"] = x[keep].astype(np.uint16)
    moved["y"] = y[keep].astype(np.uint16)
    return moved


def deblur_window(window: Events, nearby: Events, origin: tuple[int, int], shape_hw: tuple[int, int],
                  sensor_wh: tuple[int, int], cfg: DeblurConfig = DeblurConfig(),
                  prior: SmearPrior | None = None) -> tuple[Events, tuple[float, float]]:
    """The window's events deblurred, and the smear found ((0, 0): left as they were).

    ``nearby``: the sensor's events of the window's span (at least those around the window).
    ``prior``: the smear predicted from elsewhere (the gyroscope) for the window's span, searched
    only around it (``smear_near``); where it has no prediction, the full search."""
    if not cfg.enabled or window.shape[0] < 2:
        return window, (0.0, 0.0)
    t_ref, t_first = int(window["t"][-1]), int(window["t"][0])
    span = float(t_ref - t_first)
    if span < cfg.min_span_us:
        return window, (0.0, 0.0)
    region = region_of(origin, shape_hw, sensor_wh, cfg.margin_px)
    centre = (origin[0] + shape_hw[1] / 2.0, origin[1] + shape_hw[0] / 2.0)
    predicted = None if prior is None else prior.smear_prior(t_first, t_ref, centre)
    # (``nearby`` can be the sensor's tens of thousands: its fields are read in place, not selected)
    if prior is not None and predicted is not None:
        smear = smear_near(nearby["x"], nearby["y"], nearby["t"], region, t_ref, span, predicted, prior.smear_radius_px,
                           cfg, t_first_us=t_first)
    else:
        smear = smear_of(nearby["x"], nearby["y"], nearby["t"], region, t_ref, span, cfg, t_first_us=t_first)
    if np.hypot(*smear) < cfg.min_smear_px:
        return window, (0.0, 0.0)
    return deblur(window, smear, t_ref, span, origin, shape_hw), smear
