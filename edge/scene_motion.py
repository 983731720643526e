"""How far the whole scene has moved in the sensor: the head's motion, measured from all events.

The camera sits on the head, so the page moves in the sensor only when the head moves, and
every edge of it then fires. Events are binned into coarse count images (``cell_px`` pixels per
cell) over short slices of event time (``slice_us``); the shift between consecutive slices,
found by cross-correlation of the blurred images (sub-cell), is the scene's motion. Not phase
correlation: in dim light most events are shot noise, spread evenly over every spatial frequency,
and phase correlation weights each frequency alike, so the noise decides the peak: on the suite's
10-lux pages with head motion it found no peak in 80-86 % of the slices of four pages
(docs/head_motion.md); the plain correlation of blurred counts of every event finds one in 85-100 %. Each slice
is compared with a reference slice, not with the one before: sub-cell peaks are biased towards
whole cells, so summing a fraction of a cell per slice under-counted a steady motion by a sixth;
the reference moves on once the scene moved ``reanchor_cells`` from it or ``max_reference_slices``
passed (the page then looks different). The offset is the scene's motion since the stream began, on
the event clock. On a moving pattern it is within ~15 % of the true motion (plus a few pixels):
the stitcher's registration searches 16 px around the prediction and takes the rest.

Why the edge measures it: with one fused view per fixation the cloud sees the page a few times
a second, and across a return sweep the next view may overlap nothing it has; where it lands
must then be predicted from the head's motion, which sparse views cannot measure but the
periphery's events do. Each frame and view carries the offset at its time
(``FrameRecord.scene_px``), and the stitcher predicts from it. Pure: numpy, OpenCV and the compiled counting of ``edge.binning``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from darkread.edge.binning import add_cell_counts, cell_tables
from darkread.edge.events import Events
from darkread.stitch.register import parabola_vertex

CELL_PX = 8  # 1280x720 -> 160x90 cells: sub-cell correlation is still well inside the stitcher's search radius
SLICE_US = 20_000  # a walking head moves 2-8 px in this time: under a cell, so slices still look alike
# (40 ms slices halve the correlations but read the hard recordings worse, docs/head_motion.md;
# 16 px cells drifted by 20 px on a still page under noise)
MIN_EVENTS = 200  # a slice with fewer counted events holds no motion worth measuring (a still head)
MIN_PEAK_SD = 4.0  # a correlation peak less than this many standard deviations above the surface: noise, not a shift
BLUR_CELLS = 1.5  # Gaussian blur of the count images (cells): sparse counts in the dark correlate as smooth blobs
MAX_SHIFT_CELLS = 3.0  # more than this from the reference (> 1,200 px/s) is no head motion: a flicker or noise
REANCHOR_CELLS = 2.0  # the reference moves on after this much motion ...
MAX_REFERENCE_SLICES = 10  # ... or this many slices (200 ms: events of a slice change with the motion's direction)
STRIDE = 1  # every event is counted: in the dark every eighth left 2,000 events a slice over 14,400 cells, and
# the tracker's error over 200 ms on the 10-lux pages rose 1.2-1.5x (every second: 1.0-1.4x)
KEEP_SLICES = 500  # 10 s of offsets: frames ask about the last few hundred milliseconds
TRUST_US = 100_000  # an offset is reported only if no slice this long before it had events but no peak
# (at 10 lux half the slices found no peak and the rest wandered: on a still real-reader page the offset
# drifted 200 px and the page read far worse, docs/head_motion.md; unknown motion is no motion)


@dataclass(frozen=True)
class SceneMotionConfig:
    cell_px: int = CELL_PX
    slice_us: int = SLICE_US
    min_events: int = MIN_EVENTS
    min_peak_sd: float = MIN_PEAK_SD
    blur_cells: float = BLUR_CELLS
    max_shift_cells: float = MAX_SHIFT_CELLS
    reanchor_cells: float = REANCHOR_CELLS
    max_reference_slices: int = MAX_REFERENCE_SLICES
    stride: int = STRIDE
    trust_us: int = TRUST_US


def gaussian_transfer(shape_hw: tuple[int, int], sigma: float) -> np.ndarray:
    """The spectrum (``cv2.dft``'s packed real layout) of a circular Gaussian blur of ``sigma`` cells."""
    h, w = shape_hw
    dy = np.minimum(np.arange(h), h - np.arange(h))[:, None]
    dx = np.minimum(np.arange(w), w - np.arange(w))[None, :]
    kernel = np.exp(-(dx**2 + dy**2) / (2.0 * sigma**2)).astype(np.float32) if sigma > 0 else (dx + dy == 0).astype(np.float32)
    return cv2.dft(kernel / kernel.sum())


def slice_spectrum(counts: np.ndarray, window: np.ndarray) -> np.ndarray:
    """A slice's count image (any number type, ``window``'s shape) as correlated: square roots in
    float32 (a few hot pixels must not outweigh the page's edges), mean removed, tapered by
    ``window``, transformed (packed real layout)."""
    image = np.sqrt(counts, dtype=np.float32)
    image -= np.add.reduce(image, axis=None) / np.float32(image.size)  # ``image.mean()``, bit for bit, without its wrapper
    image *= window
    return cv2.dft(image)


def slice_shift(reference: np.ndarray, current: np.ndarray, cfg: SceneMotionConfig) -> tuple[float, float] | None:
    """The scene's shift (cells) from the reference slice to the slice of spectrum ``current``
    (``slice_spectrum``); ``reference``: the reference's spectrum already multiplied by the blur's
    ``gaussian_transfer`` (of sigma * sqrt 2: both images blurred by sigma; once per reference, which
    serves several slices), so their cross-correlation comes out blurred. None without a peak
    ``min_peak_sd`` standard deviations above the correlation surface, or one beyond ``max_shift_cells``."""
    surface = cv2.idft(cv2.mulSpectrums(reference, current, 0, conjB=True), flags=cv2.DFT_REAL_OUTPUT)
    _, peak, _, (px, py) = cv2.minMaxLoc(surface)
    mean, sd = cv2.meanStdDev(surface)
    if not peak - float(mean[0, 0]) >= cfg.min_peak_sd * float(sd[0, 0]) > 0:
        return None
    h, w = surface.shape
    # the peak sits at minus the shift (circularly); a parabola through its neighbours refines it
    sx = -((px + w // 2) % w - w // 2) - parabola_vertex(float(surface[py, (px - 1) % w]), peak, float(surface[py, (px + 1) % w]))
    sy = -((py + h // 2) % h - h // 2) - parabola_vertex(float(surface[(py - 1) % h, px]), peak, float(surface[(py + 1) % h, px]))
    if max(abs(sx), abs(sy)) > cfg.max_shift_cells:
        return None
    return float(sx), float(sy)


class SceneMotion:
    """Pushed events in time order, it keeps the scene's offset over time (not thread-safe)."""

    def __init__(self, sensor_wh: tuple[int, int], cfg: SceneMotionConfig = SceneMotionConfig()) -> None:
        self.cfg = cfg
        self.grid_wh = (-(-int(sensor_wh[0]) // cfg.cell_px), -(-int(sensor_wh[1]) // cfg.cell_px))
        self._window = cv2.createHanningWindow(self.grid_wh, cv2.CV_32F)
        self._transfer = gaussian_transfer(self.grid_wh[::-1], cfg.blur_cells * np.sqrt(2.0))
        self._slice_end: int | None = None
        cols, rows = self.grid_wh  # (events past the grid's last column or row count in it)
        self._column_of, self._row_of = cell_tables(cols * cfg.cell_px, rows * cfg.cell_px, cfg.cell_px)
        self._current = np.zeros(cols * rows, np.float32)  # the open slice's counts per cell (while _count > 0; whole numbers, exact in float32)
        self._count = 0
        self._reference: np.ndarray | None = None  # the reference slice's spectrum times the blur's transfer
        self._reference_offset = np.zeros(2)  # the scene's offset when the reference slice was taken
        self._reference_age = 0
        self._offset = np.zeros(2)
        self._seen = 0  # events pushed so far: which are counted does not depend on the chunking
        self._times = np.zeros(2 * KEEP_SLICES, np.int64)
        self._offsets = np.zeros((2 * KEEP_SLICES, 2), np.float64)
        self._failed = np.zeros(2 * KEEP_SLICES, bool)  # the slice ending then had events but no trustworthy peak
        self._n = 0

    def push(self, events: Events) -> None:
        """Add a chunk (time-ordered, after the chunks before it)."""
        if events.shape[0] == 0:
            return
        stride = self.cfg.stride
        first = (-self._seen) % stride
        self._seen += int(events.shape[0])
        events = events[first::stride]
        if events.shape[0] == 0:
            return
        t = events["t"]
        slice_us = self.cfg.slice_us
        if self._slice_end is None:
            self._slice_end = int(t[0]) + slice_us
            self._record(int(t[0]))
        x, y = events["x"], events["y"]
        # the slice ends this chunk passes, and where each cuts it (a running maximum keeps the
        # cuts ordered when a real sensor's times jitter back by a few microseconds)
        n_ends = max(0, (int(t[-1]) - self._slice_end) // slice_us + 1)
        cuts = np.maximum.accumulate(np.searchsorted(t, self._slice_end + slice_us * np.arange(n_ends), side="left"))
        start = 0
        for cut in cuts.tolist():
            self._count_cells(x, y, start, cut)
            self._close_slice()
            start = cut
        self._count_cells(x, y, start, x.shape[0])

    def _count_cells(self, x: np.ndarray, y: np.ndarray, start: int, stop: int) -> None:
        """Count events ``start:stop`` into the open slice (compiled: one pass, ``edge.binning``)."""
        if stop > start:
            if not self._count:  # (the slice's first events)
                self._current.fill(0)
            add_cell_counts(x, y, start, stop, self._column_of, self._row_of, self._current)
            self._count += stop - start

    def _close_slice(self) -> None:
        assert self._slice_end is not None
        cfg = self.cfg
        failed = False
        if self._count >= cfg.min_events:
            current = slice_spectrum(self._current.reshape(self._window.shape), self._window)
            shift = None if self._reference is None else slice_shift(self._reference, current, cfg)
            failed = shift is None and self._reference is not None
            if shift is not None:
                self._offset = self._reference_offset + np.asarray(shift) * cfg.cell_px
                self._reference_age += 1
            if shift is None or max(map(abs, shift)) >= cfg.reanchor_cells or self._reference_age >= cfg.max_reference_slices:
                self._reference = cv2.mulSpectrums(current, self._transfer, 0)
                self._reference_offset, self._reference_age = self._offset.copy(), 0
        # (a slice with too few events - a still head - leaves the offset and the reference as they were)
        self._record(self._slice_end, failed)
        self._count = 0  # (the next slice's first counts start from zero)
        self._slice_end += cfg.slice_us

    def _record(self, t_us: int, failed: bool = False) -> None:
        if self._n == self._times.shape[0]:  # keep the newest KEEP_SLICES (amortised: one copy per KEEP_SLICES slices)
            self._times[:KEEP_SLICES] = self._times[-KEEP_SLICES:]
            self._offsets[:KEEP_SLICES] = self._offsets[-KEEP_SLICES:]
            self._failed[:KEEP_SLICES] = self._failed[-KEEP_SLICES:]
            self._n = KEEP_SLICES
        self._times[self._n] = int(t_us)
        self._offsets[self._n] = self._offset
        self._failed[self._n] = failed
        self._n += 1

    def at(self, t_us: int) -> tuple[float, float] | None:
        """The scene's offset (sensor px, x right, y down) at ``t_us``, interpolated between slice
        ends; None before any event, or when a slice up to ``trust_us`` before it (or the one it
        falls in) had events but no trustworthy peak: the motion is unknown then (dim light, flicker)."""
        n = self._n
        if n == 0:
            return None
        times, offsets = self._times[:n], self._offsets[:n]
        first, last = np.searchsorted(times, [t_us - self.cfg.trust_us, t_us], side="left").tolist()
        if self._failed[first : min(last + 1, n)].any():
            return None
        return float(np.interp(t_us, times, offsets[:, 0])), float(np.interp(t_us, times, offsets[:, 1]))
