"""Clock offset between the glasses (device clock) and the event camera: ``t_event = t_device + offset``.

**Flash alignment.** A board flashes on a screen (glasses still, or held still at a few poses). Each switch shows up in the events as a burst
(onset on the event clock, or an edge on the external-trigger input when the screen's driver is
wired to it) and in the RGB frames (device clock) as a change of brightness. A frame whose
exposure spans a switch shows a blend whose level says *where* in the exposure the switch fell,
so the alignment is finer than the frame period. For an offset ``o`` the event-side switches
predict every frame's shown fraction; the offset minimising the squared difference to the
measured fractions is the estimate, its uncertainty a jackknife over the switches.

**Refinement by gaze movement.** While the wearer fixates a word and the head moves, the gaze
pixel moves with the page in the event image, and the event rate rises with that motion. The lag
that maximises the normalised cross-correlation of event activity and gaze speed (saccades
masked, since the eyes move but the page image does not) refines an offset to a few ms.
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from darkread.core.image_codec import ImageCodecError, read_image
from darkread.edge.calibrate.event_image import Burst
from darkread.edge.errors import CalibrationError

logger = logging.getLogger(__name__)


@dataclass
class RgbFrames:
    """RGB frames on the device clock: exposure middles, exposure lengths, grey images."""

    t_us: np.ndarray
    exposure_us: np.ndarray
    images: Sequence[np.ndarray]

    def __len__(self) -> int:
        return int(self.t_us.shape[0])


class LazyImages(Sequence):
    """Grey images read from disk when indexed (full-resolution Aria frames are 8 MB each)."""

    def __init__(self, paths: list[Path]) -> None:
        self.paths = paths

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return LazyImages(self.paths[k])
        try:
            return read_image(self.paths[k])
        except ImageCodecError:
            raise CalibrationError(f"{self.paths[k]}: cannot read image") from None


def load_rgb_frames(path: str | Path, *, max_side: int | None = 128, lazy: bool = False) -> RgbFrames:
    """Read ``rgb_frames.csv`` (``timestamp_us, exposure_us, file``; paths relative to the CSV).

    ``timestamp_us`` is the device-clock middle of the exposure (as Aria stamps frames). Frames
    are read grey and shrunk to ``max_side`` pixels (the clock needs only their brightness), or
    with ``lazy`` read at full size only when used (pose estimation looks at a few of them).
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"{path}: RGB frame list not found (rgb_frames.csv with timestamp_us, exposure_us, file)")
    times, exposures, images, paths = [], [], [], []
    with open(path, newline="", encoding="utf-8") as handle:
        for line, row in enumerate(csv.DictReader(handle), start=2):
            try:
                t, e, name = int(row["timestamp_us"]), float(row["exposure_us"]), row["file"]
            except (KeyError, TypeError, ValueError) as exc:
                raise CalibrationError(f"{path}:{line}: expected timestamp_us, exposure_us, file ({exc})") from None
            frame_path = path.parent / name
            if lazy:
                if not frame_path.is_file():
                    raise CalibrationError(f"{path}:{line}: cannot read image {name}")
            else:
                try:
                    image = read_image(frame_path)
                except ImageCodecError:
                    raise CalibrationError(f"{path}:{line}: cannot read image {name}") from None
                if max_side and max(image.shape) > max_side:
                    scale = max_side / max(image.shape)
                    image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
                images.append(image)
            times.append(t)
            exposures.append(e)
            paths.append(frame_path)
    if not times:
        raise CalibrationError(f"{path}: no frames listed")
    order = np.argsort(times)
    ordered = LazyImages([paths[i] for i in order]) if lazy else [images[i] for i in order]
    return RgbFrames(np.asarray(times, dtype=np.int64)[order], np.asarray(exposures)[order], ordered)


def _grey_stack(images: Sequence[np.ndarray], max_side: int = 128) -> np.ndarray:
    """Frames as one uint8 stack at a common small size (the clock needs brightness only)."""
    first = images[0]
    scale = min(1.0, max_side / max(first.shape))
    size = (max(1, round(first.shape[1] * scale)), max(1, round(first.shape[0] * scale)))
    return np.stack([im if im.shape[::-1] == size else cv2.resize(im, size, interpolation=cv2.INTER_AREA) for im in images])


def pose_segments(images: Sequence[np.ndarray], *, min_overlap: float = 0.8) -> np.ndarray:
    """Segment id per frame: a new segment starts when the glasses have moved.

    The screen is the bright region whether it shows the board or the blank page (Otsu threshold
    of each frame; the board's dark squares are still far brighter than a dim room), so a drop of
    its overlap with the previous frame's bright region marks a new pose.
    """
    stack = _grey_stack(images)
    masks = [cv2.threshold(im, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)[1].astype(bool) for im in stack]
    ids = np.zeros(len(masks), dtype=np.int64)
    for i in range(1, len(masks)):
        union = int(np.count_nonzero(masks[i] | masks[i - 1]))
        overlap = int(np.count_nonzero(masks[i] & masks[i - 1])) / max(union, 1)
        ids[i] = ids[i - 1] + (overlap < min_overlap)
    return ids


def linear_levels(images: Sequence[np.ndarray], *, gamma: float = 2.2, segments: np.ndarray | None = None) -> np.ndarray:
    """Per frame, the mean linear brightness of the pixels that change most within its pose.

    Frames are sRGB-like encoded, and exposures mix *light*, so levels are averaged after undoing
    the gamma. Only the pixels whose brightness varies most (top 20 %) within a pose segment
    count: the flashing screen, not the room.
    """
    linear = (_grey_stack(images).astype(np.float32) / 255.0) ** gamma
    seg = np.zeros(len(linear), dtype=np.int64) if segments is None else np.asarray(segments)
    levels = np.empty(len(linear))
    for s in np.unique(seg):
        rows = np.flatnonzero(seg == s)
        spread = linear[rows].std(axis=0)
        mask = spread >= np.percentile(spread, 80)
        levels[rows] = linear[rows][:, mask].mean(axis=1)
    return levels


def shown_fractions(
    levels: np.ndarray, *, window: int = 15, min_contrast: float = 0.05, segments: np.ndarray | None = None
) -> np.ndarray:
    """Measured share of each exposure with the board shown (0..1); NaN where it cannot be told.

    Showing the board darkens the screen (dark squares on a white page), so within a window of
    ``window`` frames either side (and within the frame's pose segment) the brightest level is
    "blank" and the darkest "shown"; a segment that never shows both gives NaN.
    """
    n = levels.shape[0]
    seg = np.zeros(n, dtype=np.int64) if segments is None else np.asarray(segments)
    out = np.full(n, np.nan)
    for i in range(n):  # a few hundred frames
        lo, hi = max(0, i - window), min(n, i + window + 1)
        same = levels[lo:hi][seg[lo:hi] == seg[i]]
        bright, dark = np.max(same), np.min(same)
        if bright - dark >= min_contrast * max(bright, 1e-9):
            out[i] = np.clip((bright - levels[i]) / (bright - dark), 0.0, 1.0)
    return out


def measured_fractions(images: Sequence[np.ndarray]) -> np.ndarray:
    """Shown fraction of every frame, poses told apart by ``pose_segments``."""
    segments = pose_segments(images)
    return shown_fractions(linear_levels(images, segments=segments), segments=segments)


def predicted_fractions(switch_us: np.ndarray, shown_after: np.ndarray, t_mid: np.ndarray, exposure: np.ndarray) -> np.ndarray:
    """Share of each exposure with the board shown, for switches on the same clock as ``t_mid``."""
    order = np.argsort(switch_us)
    times = np.asarray(switch_us, dtype=np.float64)[order]
    states = np.asarray(shown_after, dtype=bool)[order]
    t0 = (np.asarray(t_mid, dtype=np.float64) - exposure / 2)[:, None]
    t1 = (np.asarray(t_mid, dtype=np.float64) + exposure / 2)[:, None]
    if times.size == 0:
        return np.zeros(t0.shape[0])
    # the state before the first switch is the opposite of what it switched to
    starts = np.concatenate([[-np.inf], times])[None, :]
    ends = np.concatenate([times, [np.inf]])[None, :]
    level = np.concatenate([[not states[0]], states]).astype(np.float64)
    overlap = np.clip(np.minimum(t1, ends) - np.maximum(t0, starts), 0.0, None)
    return (overlap @ level) / np.maximum((t1 - t0)[:, 0], 1e-9)


@dataclass
class ClockResult:
    offset_us: float
    uncertainty_us: float
    n_switches: int
    n_frames: int
    n_mixed_frames: int  # frames whose exposure spans a switch (they carry the sub-frame timing)
    rms_fraction: float  # RMS difference measured vs predicted shown fraction
    source: str  # "bursts" or "trigger"

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("offset_us", "uncertainty_us", "n_switches", "n_frames", "n_mixed_frames", "rms_fraction", "source")}


def switches_from_bursts(bursts: list[Burst]) -> tuple[np.ndarray, np.ndarray]:
    """(event-clock switch times, board shown after): the board appearing makes an OFF burst."""
    times = np.array([b.onset_us for b in bursts], dtype=np.float64)
    shown_after = np.array([b.polarity == 0 for b in bursts], dtype=bool)
    return times, shown_after


def switches_from_triggers(triggers: np.ndarray, *, channel: int | None = None, rising_means_shown: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(event-clock switch times, board shown after) from external-trigger edges."""
    trig = triggers if channel is None else triggers[triggers["id"] == channel]
    if trig.size == 0:
        raise CalibrationError("no external-trigger edges in the stream" + (f" on channel {channel}" if channel is not None else ""))
    rising = trig["p"] == 1
    return trig["t"].astype(np.float64), rising if rising_means_shown else ~rising


def _cost(offset: float, switch_event: np.ndarray, shown_after: np.ndarray, frames_t: np.ndarray, exposure: np.ndarray,
          measured: np.ndarray) -> float:
    pred = predicted_fractions(switch_event - offset, shown_after, frames_t, exposure)
    return float(np.mean((pred - measured) ** 2))


def _coarse_offsets(switch_event: np.ndarray, shown_after: np.ndarray, frames_t: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Candidate offsets: every event switch against every frame-side switch of the same direction."""
    frac = np.nan_to_num(measured, nan=0.5)
    step = np.diff(frac)
    up = np.flatnonzero(step > 0.5)  # board appeared between frame i and i + 1
    down = np.flatnonzero(step < -0.5)
    candidates = []
    for idx, state in ((up, True), (down, False)):
        device = (frames_t[idx] + frames_t[idx + 1]) / 2
        ev = switch_event[shown_after == state]
        if device.size and ev.size:
            candidates.append((ev[:, None] - device[None, :]).ravel())
    return np.concatenate(candidates) if candidates else np.zeros(0)


def fit_offset(
    switch_event: np.ndarray,
    shown_after: np.ndarray,
    frames: RgbFrames,
    *,
    prior_us: float | None = None,
    search_us: float | None = None,
    source: str = "bursts",
) -> ClockResult:
    """Offset (device -> event) that best predicts the frames' shown fractions from the switches."""
    if switch_event.size < 2:
        raise CalibrationError(f"need at least 2 switches of the flashing board, found {switch_event.size}")
    measured = measured_fractions(frames.images)
    ok = np.isfinite(measured)
    t, e, m = frames.t_us[ok].astype(np.float64), frames.exposure_us[ok], measured[ok]
    if t.size < 4:
        raise CalibrationError("the RGB frames do not show the flashing board (no brightness change)")
    period = float(np.median(np.diff(t)))
    if prior_us is not None and search_us is not None:
        centre = float(prior_us)
    else:
        cands = _coarse_offsets(switch_event, shown_after, t, m)
        if cands.size == 0:
            raise CalibrationError("could not pair event bursts with brightness changes in the RGB frames")
        # the true offset is the one most switches agree on within a frame period
        cands = np.sort(cands)
        support = np.searchsorted(cands, cands + period, side="right") - np.searchsorted(cands, cands - period, side="left")
        best = cands[support == support.max()]
        scores = [_cost(c, switch_event, shown_after, t, e, m) for c in best]
        centre = float(best[int(np.argmin(scores))])
    span = search_us if search_us is not None else 1.5 * period

    def refine(sw: np.ndarray, states: np.ndarray, tt: np.ndarray, ee: np.ndarray, mm: np.ndarray, around: float, half: float) -> float:
        step = max(half / 150, 20.0)
        grid = around + np.arange(-half, half + 1e-9, step)
        costs = np.array([_cost(o, sw, states, tt, ee, mm) for o in grid])
        best = grid[int(np.argmin(costs))]
        fine = best + np.linspace(-step, step, 41)
        fine_costs = np.array([_cost(o, sw, states, tt, ee, mm) for o in fine])
        return float(fine[int(np.argmin(fine_costs))])

    offset = refine(switch_event, shown_after, t, e, m, centre, span)
    pred = predicted_fractions(switch_event - offset, shown_after, t, e)
    mixed = (pred > 0.02) & (pred < 0.98)
    # jackknife over switches: drop one switch and the frames within a period of it
    left_out = []
    for k in range(switch_event.size):
        keep_sw = np.arange(switch_event.size) != k
        near = np.abs(t - (switch_event[k] - offset)) < period + e
        left_out.append(refine(switch_event[keep_sw], shown_after[keep_sw], t[~near], e[~near], m[~near], offset, period / 4))
    estimates = np.asarray(left_out)
    n = estimates.size
    jack = float(np.sqrt((n - 1) / n * np.sum((estimates - estimates.mean()) ** 2)))
    return ClockResult(
        offset_us=offset,
        uncertainty_us=max(jack, 10.0),
        n_switches=int(switch_event.size),
        n_frames=int(t.size),
        n_mixed_frames=int(np.count_nonzero(mixed)),
        rms_fraction=float(np.sqrt(np.mean((pred - m) ** 2))),
        source=source,
    )


# -- refinement from a reading recording ---------------------------------------------------------


@dataclass
class RefineResult:
    offset_us: float
    correction_us: float  # refined minus initial offset
    peak_correlation: float  # below ~0.3 the recording has too little head motion to judge the clock
    uncertainty_us: float  # jackknife over consecutive stretches of the recording
    lags_us: np.ndarray
    correlation: np.ndarray

    def to_dict(self) -> dict:
        return {
            "offset_us": self.offset_us, "correction_us": self.correction_us,
            "peak_correlation": self.peak_correlation, "uncertainty_us": self.uncertainty_us,
        }


def gaze_speed(
    t_device_us: np.ndarray, pixels: np.ndarray, *, saccade_px_per_s: float, span: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sample times, speed px/s, fixation mask) of a gaze pixel track.

    Speeds are central differences over ``span`` samples either side (symmetric, so they add no
    lag, and they average the tracker's per-sample noise). A speed counts only if no step inside
    its span is a saccade or a gap.
    """
    ok = np.isfinite(pixels).all(axis=1)
    t, uv = t_device_us[ok].astype(np.float64), pixels[ok]
    if t.size < 2 * span + 3:
        raise CalibrationError("too few valid gaze samples to refine the clock")
    dt = np.diff(t) * 1e-6
    step_speed = np.linalg.norm(np.diff(uv, axis=0), axis=1) / np.maximum(dt, 1e-6)
    # a noisy tracker jitters faster than a fixed threshold: saccades stand out above the noise
    threshold = max(saccade_px_per_s, 3.0 * float(np.median(step_speed)))
    bad_step = (step_speed >= threshold) | (dt > 0.05)
    centre = np.arange(span, t.size - span)
    v = np.linalg.norm(uv[centre + span] - uv[centre - span], axis=1) / ((t[centre + span] - t[centre - span]) * 1e-6)
    cum = np.concatenate([[0], np.cumsum(bad_step)])
    fixation = (cum[centre + span] - cum[centre - span]) == 0
    return t[centre], v, fixation


def _peak(lags: np.ndarray, corr: np.ndarray) -> tuple[float, int]:
    """Lag of the correlation maximum, refined by a parabola through its neighbours."""
    k = int(np.nanargmax(corr))
    lag = float(lags[k])
    if 0 < k < lags.size - 1 and np.isfinite(corr[k - 1]) and np.isfinite(corr[k + 1]):
        denom = corr[k - 1] - 2 * corr[k] + corr[k + 1]
        if denom < 0:
            lag += 0.5 * (corr[k - 1] - corr[k + 1]) / denom * float(lags[1] - lags[0])
    return lag, k


class ActivityCounter:
    """Events per time bin, accumulated chunk by chunk (recordings larger than memory stream through)."""

    def __init__(self, bin_us: float = 2_000.0) -> None:
        self.bin_us = int(bin_us)
        self.start_us: int | None = None
        self.counts = np.zeros(0, dtype=np.int64)

    def add(self, t_us: np.ndarray) -> None:
        t = np.asarray(t_us, dtype=np.int64)
        if t.size == 0:
            return
        if self.start_us is None:
            self.start_us = int(t[0])
        idx = np.maximum((t - self.start_us) // self.bin_us, 0).astype(np.intp)
        chunk = np.bincount(idx)
        if chunk.size > self.counts.size:
            self.counts = np.concatenate([self.counts, np.zeros(chunk.size - self.counts.size, dtype=np.int64)])
        self.counts[: chunk.size] += chunk


def refine_offset(
    event_t_us: np.ndarray | ActivityCounter,
    gaze_t_device_us: np.ndarray,
    gaze_pixels: np.ndarray,
    initial_offset_us: float,
    *,
    search_us: float = 40_000.0,
    step_us: float = 100.0,
    bin_us: float = 2_000.0,
    saccade_px_per_s: float = 600.0,
    n_blocks: int = 5,
) -> RefineResult:
    """Lag that best aligns event activity with gaze speed during fixations.

    ``event_t_us`` are event times or an ``ActivityCounter`` filled from a stream (its bin wins).
    ``gaze_pixels`` are the gaze positions in the event image (a constant error in them does not
    matter: only their speed counts). Events are counted in ``bin_us`` bins; for each candidate
    offset the gaze speed is interpolated at every bin's device time and the correlation over
    fixation bins computed; the peak is refined by a parabola. The uncertainty is a jackknife over
    ``n_blocks`` consecutive stretches of the recording.
    """
    mid, speed, fixation = gaze_speed(np.asarray(gaze_t_device_us), np.asarray(gaze_pixels, dtype=np.float64), saccade_px_per_s=saccade_px_per_s)
    if isinstance(event_t_us, ActivityCounter):
        activity = event_t_us
    else:
        activity = ActivityCounter(bin_us)
        activity.add(event_t_us)
    if activity.start_us is None:
        raise CalibrationError("no events to refine the clock with")
    bin_us = float(activity.bin_us)
    start = activity.start_us
    counts = activity.counts.astype(np.float64)
    n_bins = counts.size
    centres = start + (np.arange(n_bins) + 0.5) * bin_us
    block = np.minimum((np.arange(n_bins) * n_blocks) // n_bins, n_blocks - 1)
    lags = np.arange(-search_us, search_us + 1e-9, step_us)
    # per lag and block: n, sum a, sum b, sum ab, sum a^2, sum b^2 (so any subset's correlation follows)
    sums = np.zeros((lags.size, n_blocks, 6))
    fix_f = fixation.astype(np.float64)
    for i, lag in enumerate(lags):
        td = centres - (initial_offset_us + lag)
        use = (td > mid[0]) & (td < mid[-1])
        use[use] = np.interp(td[use], mid, fix_f) > 0.999
        a = counts[use]
        b = np.interp(td[use], mid, speed)
        blk = block[use]
        for j, column in enumerate((np.ones_like(a), a, b, a * b, a * a, b * b)):
            sums[i, :, j] = np.bincount(blk, weights=column, minlength=n_blocks)

    def correlation(total: np.ndarray) -> np.ndarray:
        n, sa, sb, sab, saa, sbb = np.moveaxis(total, -1, 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            cov = sab / n - sa * sb / n**2
            var = (saa / n - (sa / n) ** 2) * (sbb / n - (sb / n) ** 2)
            return np.where((n >= 10) & (var > 0), cov / np.sqrt(var), np.nan)

    corr = correlation(sums.sum(axis=1))
    if not np.isfinite(corr).any():
        raise CalibrationError(
            f"no usable overlap of gaze fixations ({int(fixation.sum())} of {fixation.size} samples) and events "
            "within the search range: check the initial offset, or record with more head motion"
        )
    lag, k = _peak(lags, corr)
    leave_out = []
    for j in range(n_blocks):
        c = correlation(sums.sum(axis=1) - sums[:, j])
        if np.isfinite(c).any():
            leave_out.append(_peak(lags, c)[0])
    m = len(leave_out)
    jack = float(np.sqrt((m - 1) / m * np.sum((np.asarray(leave_out) - np.mean(leave_out)) ** 2))) if m > 1 else float(search_us)
    return RefineResult(
        offset_us=initial_offset_us + lag,
        correction_us=lag,
        peak_correlation=float(corr[k]),
        uncertainty_us=max(jack, step_us / 2),
        lags_us=lags,
        correlation=corr,
    )
