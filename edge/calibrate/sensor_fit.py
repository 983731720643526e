"""The fits of ``darkread calibrate sensor``: arrays in, numbers out (docs/calibration.md, "Sensor").

- **Background activity** of a still, uniform card: ON + OFF events per pixel and second, hot pixels
  left out (:func:`background_rate`).
- **The photoreceptor's time constant** from a bright edge swept over a dark field. After a step, a
  first-order pixel's log signal approaches its new level as 1 - exp(-s / tau); with the reference
  at a uniformly random phase within a threshold (as after any history of events), the expected number
  of crossings up to a lag s is proportional to that distance, so the events' lags behind the step are
  exponentially distributed with mean tau, whatever the threshold and the edge's contrast. The early
  lags are distorted (refractory period, the edge's transit across a pixel, the optics' blur), the
  later lags are not: the exponential's memorylessness lets the fit use only lags beyond a start ``s0``
  and measure them from any per-pixel origin that is off by a constant. The origin is a plane through
  the pixels' median ON time (a straight edge at steady speed), the window 0.7 to 3.7 time constants
  (plus the edge's transit) behind it. Background events are a uniform component of the likelihood, at
  the larger of their density before the edge and well after it: after the step, the background
  activity's own slow fluctuations keep completing crossings the step left near threshold (ON events
  at the noise's bandwidth, tens of ms), a tail a long window would mistake for a slow pixel
  (:func:`edge_time_constant`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

MIN_EDGE_EVENTS_PER_PIXEL = 3  # a pixel with fewer ON events did not see the edge (or only its noise)
MIN_EDGE_PIXELS = 20
MIN_TAIL_EVENTS = 50
TAIL_START_TAUS = 0.7  # the window starts this many time constants (plus the transit) after the origin
TAIL_LENGTH_TAUS = 3.0
BEFORE_GAP_TAUS = 2.0  # the background window before the edge ends this many time constants before the origin
LATE_WINDOW_AT = 1.5  # the late background window starts this many window lengths after the window's end
HOT_SIGMAS = 10.0  # a pixel whose count exceeds the mean by this many Poisson sds (+10 events) is hot


@dataclass(frozen=True)
class BackgroundRate:
    """Background activity of one still recording."""

    rate_hz: float  # ON + OFF events per pixel and second
    on_hz: float
    off_hz: float
    pixels: int  # pixels counted (the events' bounding box less hot pixels)
    hot_pixels: int
    seconds: float  # the time counted

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class EdgeFit:
    """The photoreceptor's time constant measured behind a moving edge."""

    time_constant_s: float
    tail_events: int
    background_events: float  # the expected background events inside the tail window
    edge_pixels: int
    speed_px_s: float  # of the fitted arrival plane
    tail_start_s: float
    tail_length_s: float

    def to_dict(self) -> dict:
        return {"time_constant_us": round(self.time_constant_s * 1e6, 2), "tail_events": self.tail_events,
                "background_events": round(self.background_events, 2), "edge_pixels": self.edge_pixels,
                "speed_px_s": round(self.speed_px_s, 1), "tail_start_us": round(self.tail_start_s * 1e6, 1),
                "tail_length_us": round(self.tail_length_s * 1e6, 1)}


def background_rate(x: np.ndarray, y: np.ndarray, p: np.ndarray, t_us: np.ndarray, t0_us: float, t1_us: float) -> BackgroundRate:
    """ON + OFF events per pixel and second between ``t0_us`` and ``t1_us`` over the bounding box of the
    pixels that fired (a recording of the card alone, or an ROI inside it), hot pixels left out."""
    seconds = (t1_us - t0_us) * 1e-6
    if seconds <= 0:
        raise ValueError("the recording is too short to count its background (nothing left after the warm-up)")
    keep = (t_us >= t0_us) & (t_us < t1_us)
    x, y, p = x[keep].astype(np.int64), y[keep].astype(np.int64), p[keep]
    if x.size == 0:
        return BackgroundRate(0.0, 0.0, 0.0, 0, 0, seconds)
    x0, y0 = int(x.min()), int(y.min())
    w, h = int(x.max()) - x0 + 1, int(y.max()) - y0 + 1
    pix = (y - y0) * w + (x - x0)
    counts = np.bincount(pix, minlength=w * h)
    hot = np.zeros(counts.size, dtype=bool)
    for _ in range(3):  # the mean without the hot pixels, then the hot pixels against it
        mean = counts[~hot].mean()
        hot = counts > mean + HOT_SIGMAS * math.sqrt(mean) + 10
    good = ~hot[pix]
    n = int((~hot).sum())
    on = float(np.count_nonzero(p[good] == 1)) / (n * seconds)
    off = float(np.count_nonzero(p[good] == 0)) / (n * seconds)
    return BackgroundRate(on + off, on, off, n, int(hot.sum()), seconds)


def median_times(pix: np.ndarray, t_us: np.ndarray, min_events: int) -> tuple[np.ndarray, np.ndarray]:
    """The pixels with at least ``min_events`` events and the median time of each."""
    order = np.lexsort((t_us, pix))
    pix_s, t_s = pix[order], t_us[order]
    ids, start, count = np.unique(pix_s, return_index=True, return_counts=True)
    ok = count >= min_events
    ids, start, count = ids[ok], start[ok], count[ok]
    lo = t_s[start + (count - 1) // 2]
    hi = t_s[start + count // 2]
    return ids, 0.5 * (lo + hi)


def arrival_plane(x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Least-squares t = a + b x + c y, refitted without the points off by more than 3 MADs."""
    a = np.column_stack([np.ones_like(x), x, y]).astype(np.float64)
    keep = np.ones(x.size, dtype=bool)
    coef: np.ndarray = np.zeros(3)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(a[keep], t[keep].astype(np.float64), rcond=None)
        resid = t - a @ coef
        mad = float(np.median(np.abs(resid[keep] - np.median(resid[keep])))) + 1e-9
        keep = np.abs(resid - np.median(resid[keep])) <= 3.0 * 1.4826 * mad
        if keep.sum() < 3:
            break
    return coef


def truncated_exponential_tau(lags: np.ndarray, length: float, background: float) -> float:
    """Maximum-likelihood mean of an exponential seen on [0, ``length``) (``lags`` from the window's
    start), beside ``background`` uniform events expected in the window. Searched on a log grid, refined."""
    n = lags.size
    w = max(n - background, 0.0) / n
    lags = lags.astype(np.float64)

    def loglik(taus: np.ndarray) -> np.ndarray:
        taus = taus[:, None]
        signal = np.exp(-lags[None, :] / taus) / (taus * -np.expm1(-length / taus))
        return np.log(w * signal + (1.0 - w) / length).sum(axis=1)

    grid = np.geomspace(length / 300.0, length * 30.0, 120)
    best = int(np.argmax(loglik(grid)))
    fine = np.geomspace(grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)], 81)
    return float(fine[int(np.argmax(loglik(fine)))])


def edge_time_constant(x: np.ndarray, y: np.ndarray, p: np.ndarray, t_us: np.ndarray, width: int) -> EdgeFit:
    """The photoreceptor's time constant from the ON events of a bright edge swept once across a dark
    field (see the module's docstring). ValueError when the recording holds no such edge."""
    on = p == 1
    x, y, t = x[on].astype(np.int64), y[on].astype(np.int64), t_us[on].astype(np.float64)
    pix = y * int(width) + x
    ids, med = median_times(pix, t, MIN_EDGE_EVENTS_PER_PIXEL)
    if ids.size < MIN_EDGE_PIXELS:
        raise ValueError(f"only {ids.size} pixels saw the edge (at least {MIN_EDGE_PIXELS} with "
                         f"{MIN_EDGE_EVENTS_PER_PIXEL}+ ON events needed): sweep a bright edge over a dark field in view")
    coef = arrival_plane((ids % width).astype(np.float64), (ids // width).astype(np.float64), med)
    edge = np.isin(pix, ids)
    lags = (t - (coef[0] + coef[1] * x + coef[2] * y))[edge] * 1e-6
    transit = math.hypot(coef[1], coef[2]) * 1e-6  # seconds per pixel of the edge's sweep
    speed = 1.0 / transit if transit > 0 else math.inf
    positive = lags[lags > 0]
    tau = float(positive.mean()) if positive.size else 1e-3
    tail = lags[:0]
    start = length = expected_background = 0.0
    for _ in range(6):
        start = TAIL_START_TAUS * tau + transit
        length = TAIL_LENGTH_TAUS * tau
        tail = lags[(lags >= start) & (lags < start + length)] - start
        gap = BEFORE_GAP_TAUS * tau + transit  # the pixels' first events come up to ~tau ln 2 before the plane
        before = np.count_nonzero((lags < -gap) & (lags >= -gap - length))  # the same window before the edge
        late_start = start + (1.0 + LATE_WINDOW_AT) * length  # after the exponential, before the noise settles
        late = np.count_nonzero((lags >= late_start) & (lags < late_start + length))
        expected_background = float(max(before, late))
        if tail.size < MIN_TAIL_EVENTS:
            break
        new = truncated_exponential_tau(tail, length, expected_background)
        converged = abs(new - tau) < 0.005 * tau
        tau = new
        if converged:
            break
    if tail.size < MIN_TAIL_EVENTS:
        raise ValueError(f"only {tail.size} events in the tail behind the edge (at least {MIN_TAIL_EVENTS}): "
                         "sweep the edge over more of the view, or keep recording longer after it passed")
    return EdgeFit(tau, int(tail.size), expected_background, int(ids.size), speed, start, length)


def noise_rate_at(irradiance: np.ndarray | float, levels: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """The measured noise curve at scene irradiance ``irradiance`` (lux x reflectance): log rate linear
    in log irradiance between the measured ``levels`` (> 0), flat below the lowest, extrapolated above
    the highest with the last segment's slope (never rising)."""
    order = np.argsort(levels)
    lx, ly = np.log(np.asarray(levels, np.float64)[order]), np.log(np.maximum(np.asarray(rates, np.float64)[order], 1e-6))
    q = np.log(np.maximum(np.atleast_1d(np.asarray(irradiance, np.float64)), 1e-12))
    out = np.interp(q, lx, ly)
    if lx.size >= 2:
        slope = min((ly[-1] - ly[-2]) / (lx[-1] - lx[-2]), 0.0)
        above = q > lx[-1]
        out[above] = ly[-1] + slope * (q[above] - lx[-1])
    return np.exp(out)
