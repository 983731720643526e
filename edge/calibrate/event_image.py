"""Event slices -> images a marker detector can read, and the bursts a flashing target makes.

A target on a screen that switches between the pattern and a blank white page makes every dark
part of the pattern fire at once (OFF when the pattern appears, ON when it goes), while the white
parts stay silent. Counting the events of one burst per pixel therefore fills the dark squares
and markers in solid, unlike the thin edges that motion gives; inverting the counts gives the
pattern back, dark on white. Isolated noise and hot pixels are removed with a median filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE


@dataclass(frozen=True)
class Burst:
    """A short interval in which far more pixels fire than the background rate explains."""

    onset_us: float  # when the excess activity starts (event clock)
    start_us: int  # first bin of the burst
    end_us: int  # end of the last bin of the burst
    n_events: int  # events in the burst (background included)
    on_fraction: float  # share of ON events: ~0 when the pattern appears, ~1 when it goes

    @property
    def polarity(self) -> int:
        """1 when the scene brightened (ON burst), 0 when it darkened."""
        return int(self.on_fraction >= 0.5)


def count_image(events: np.ndarray, width: int, height: int, *, polarity: int | None = None) -> np.ndarray:
    """Events per pixel (float32 [height, width]); ``polarity`` 0 or 1 keeps only that polarity."""
    if events.dtype != EVENT_CD_DTYPE:
        raise ValueError(f"events must have EVENT_CD_DTYPE, got {events.dtype}")
    keep = (events["x"] < width) & (events["y"] < height)
    if polarity is not None:
        keep &= events["p"] == polarity
    pixel = events["y"][keep].astype(np.intp) * width + events["x"][keep]
    return np.bincount(pixel, minlength=width * height).astype(np.float32).reshape(height, width)


def denoise(counts: np.ndarray, *, median_px: int = 3) -> np.ndarray:
    """Median filter: drops isolated background events and hot pixels, keeps filled areas and edges."""
    if median_px <= 1:
        return counts.astype(np.float32)
    return cv2.medianBlur(counts.astype(np.float32), median_px)


def detection_image(
    events: np.ndarray,
    width: int,
    height: int,
    *,
    median_px: int = 3,
    blur_sigma_px: float = 0.7,
    more_events_is_dark: bool = True,
) -> np.ndarray:
    """uint8 image of a burst for a marker detector.

    Screen flashing between the pattern and white (default): the pattern's dark parts are what
    fired, so many events -> dark, silent white parts -> white. Screen flashing between black and
    the pattern (``more_events_is_dark=False``): the white parts fire, so many events -> white; the
    counts are stretched between the 2nd and 98th percentile of the pixels that fired. (For a
    printed page lit by a lamp use ``latency_image``.) The light Gaussian blur turns graded counts
    at edges into smooth ramps, which sub-pixel corner refinement needs.
    """
    counts = denoise(count_image(events, width, height), median_px=median_px)
    if blur_sigma_px > 0:
        counts = cv2.GaussianBlur(counts, (0, 0), blur_sigma_px)
    fired = counts[counts > 0]
    if more_events_is_dark:
        top = float(np.percentile(fired, 95)) if fired.size else 1.0
        level = np.clip(counts / max(top, 1e-6), 0.0, 1.0)
        return np.round(255.0 * (1.0 - level)).astype(np.uint8)
    lo, hi = (np.percentile(fired, [2, 98]) if fired.size else (0.0, 1.0))
    level = np.clip((counts - lo) / max(float(hi - lo), 1e-6), 0.0, 1.0)
    return np.round(255.0 * level).astype(np.uint8)


def latency_image(
    events: np.ndarray, width: int, height: int, t_switch_us: float, *, polarity: int = 1, median_px: int = 3, blur_sigma_px: float = 1.2
) -> np.ndarray:
    """uint8 image of how soon each pixel fired after a lamp was switched on: early = white.

    A pixel's photoreceptor gets faster with its light, so white paper fires within microseconds
    and black ink hundreds of microseconds later. Unlike event counts (which the refractory period
    and the log response make non-monotonic in brightness) the first-event latency falls
    monotonically with brightness, so static printed markers come out dark on white. Pixels that
    never fired are black. Latencies are ranked (histogram-equalised): they span decades.
    """
    if events.dtype != EVENT_CD_DTYPE:
        raise ValueError(f"events must have EVENT_CD_DTYPE, got {events.dtype}")
    keep = (events["p"] == polarity) & (events["t"] >= t_switch_us) & (events["x"] < width) & (events["y"] < height)
    ev = events[keep]
    first = np.full(width * height, np.inf)
    np.minimum.at(first, ev["y"].astype(np.intp) * width + ev["x"], (ev["t"] - t_switch_us).astype(np.float64))
    fired = np.isfinite(first)
    if not fired.any():
        return np.zeros((height, width), dtype=np.uint8)
    # rank (histogram-equalise) the latencies: their spread spans decades, from paper to ink
    latency = first[fired]
    rank = np.empty(latency.size)
    rank[np.argsort(latency, kind="stable")] = np.arange(latency.size) / latency.size
    flat = np.zeros(width * height)
    flat[fired] = np.clip(1.0 - rank / 0.95, 0.0, 1.0)
    level: np.ndarray = flat.astype(np.float32).reshape(height, width)
    if median_px > 1:
        level = cv2.medianBlur(level, median_px)
    if blur_sigma_px > 0:
        level = cv2.GaussianBlur(level, (0, 0), blur_sigma_px)
    return np.round(255.0 * level).astype(np.uint8)


def activity(t_us: np.ndarray, bin_us: int, t0_us: int | None = None, t1_us: int | None = None) -> tuple[int, np.ndarray]:
    """(first bin start, events per bin) over [t0, t1)."""
    t = np.asarray(t_us, dtype=np.int64)
    if t.size == 0:
        return int(t0_us or 0), np.zeros(0, dtype=np.int64)
    start = int(t[0] if t0_us is None else t0_us)
    stop = int(t[-1] + 1 if t1_us is None else t1_us)
    n_bins = max(1, -(-(stop - start) // bin_us))
    inside = (t >= start) & (t < stop)
    return start, np.bincount((t[inside] - start) // bin_us, minlength=n_bins)[:n_bins]


def find_bursts(
    events: np.ndarray,
    *,
    bin_us: int = 1000,
    min_excess: float = 8.0,
    min_events: int = 2000,
    merge_gap_bins: int = 3,
    onset_fraction: float = 0.05,
) -> list[Burst]:
    """Bursts of activity in an event stream (time-sorted), each with a sub-bin onset time.

    A bin belongs to a burst when its count exceeds the median bin by ``min_excess`` times the
    Poisson spread of the median (at least 20 events); bins closer than ``merge_gap_bins`` join one
    burst. The onset is where the burst's cumulative *excess* over the background reaches
    ``onset_fraction`` of its total, which is robust to a few early noise events.
    """
    t = events["t"]
    if t.size == 0:
        return []
    start, counts = activity(t, bin_us)
    background = float(np.median(counts))
    threshold = background + max(min_excess * np.sqrt(max(background, 1.0)), 20.0)
    hot = np.flatnonzero(counts > threshold)
    if hot.size == 0:
        return []
    groups = np.split(hot, np.flatnonzero(np.diff(hot) > merge_gap_bins) + 1)
    bursts = []
    rate_per_us = background / bin_us
    for g in groups:
        b0, b1 = int(g[0]), int(g[-1]) + 1
        lo, hi = start + max(b0 - 2, 0) * bin_us, start + b1 * bin_us
        i0, i1 = np.searchsorted(t, [lo, hi])
        if i1 - i0 < min_events:
            continue
        window = events[i0:i1]
        tw = window["t"].astype(np.float64)
        excess = np.arange(1, tw.size + 1) - rate_per_us * (tw - lo)
        target = onset_fraction * excess[-1]
        k = int(np.searchsorted(np.maximum.accumulate(excess), target))
        onset = float(tw[min(k, tw.size - 1)])
        bursts.append(
            Burst(
                onset_us=onset,
                start_us=int(start + b0 * bin_us),
                end_us=int(hi),
                n_events=int(i1 - i0),
                on_fraction=float(np.count_nonzero(window["p"]) / window.size),
            )
        )
    return bursts


def burst_events(events: np.ndarray, burst: Burst, *, span_us: int = 20_000) -> np.ndarray:
    """The events of ``burst`` from its onset over ``span_us`` (or to its end, whichever is later)."""
    t = events["t"]
    lo = int(np.floor(burst.onset_us)) - 500
    hi = max(burst.end_us, int(burst.onset_us) + span_us)
    i0, i1 = np.searchsorted(t, [lo, hi])
    return events[i0:i1]
