"""How much light the sensor sees, from its own background events, and which bias profile that calls for.

Where the scene is still an event camera still fires: background activity, whose rate per pixel
depends on the light (docs/sensor_model.md). The glasses count every event in coarse tiles over a
slice of event time; tiles a moving edge crossed fire far more, and so do dark surfaces (the ink, a
desk: a pixel's background rate follows the light on *it*), so the background is a low quantile of
the tiles' rates, the brightest still surfaces in view (the gaze window's tiles left out: the page
being read moves most). At that low a quantile a tile's own counting noise pulls the rate down, so
the quantile is read as a Poisson count's (:func:`poisson_mean_of_quantile`). The grounded
sensor model's curve of that rate against lux, per bias profile, is shipped as data
(``edge/sources/evk4/background_rates.json``, made by ``darkread synth background-table``): the
estimator reads it on the profile the sensor runs, since the ``dark`` profile is itself noisier.

The curve is not monotonic: it rises from a dark-current floor to a peak near 1-3 lux and falls
above. The decision (enter the dark profile below ``dark_below_lux``, leave it above
``bright_above_lux``) lies on the falling side, so a rate is read there: rates above the peak read
as the peak's lux, and the dark floor's rate as the lux on the falling side with that rate, which
is darker than both thresholds (a test holds the shipped table to that). Which profile follows is a
hysteresis with a minimum dwell time (:func:`next_profile`). Pure: numpy only; the controller that
feeds it and writes the biases is ``edge/bias_control.py``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from statistics import NormalDist

import numpy as np

from darkread.edge.events import Events
from darkread.edge.sources.evk4.bias_profiles import DARK, FACTORY

BACKGROUND_RATES = Path(__file__).resolve().parent / "sources" / "evk4" / "background_rates.json"
TILE_PX = 40  # 1280x720 -> 32x18 tiles of 1600 pixels: ~160-2,000 background events each per second
STILL_QUANTILE = 0.05  # the background: this quantile of the tiles' rates (moving edges and dark surfaces make the rest)
MIN_TILES = 12  # fewer usable tiles than this: no estimate


@dataclass(frozen=True)
class RateCurve:
    """Background events (ON + OFF) per pixel and second of a still page at each lux, one bias profile."""

    lux: np.ndarray  # increasing
    rate_hz: np.ndarray
    dark_hz: float  # no light at all

    def lux_of(self, rate_hz: float | np.ndarray) -> np.ndarray:
        """The lux on the curve's falling side (above its peak) at which it has ``rate_hz``: rates above
        the peak read as the peak's lux, rates below the brightest entry as that entry's lux."""
        peak = int(np.argmax(self.rate_hz))
        falling = np.minimum.accumulate(self.rate_hz[peak:])  # monotone despite the table's own noise
        log_rate = np.log(np.maximum(falling, 1e-9)) - np.arange(falling.size) * 1e-9  # strictly decreasing
        rate = np.log(np.maximum(np.asarray(rate_hz, dtype=np.float64), 1e-9))
        return np.exp(np.interp(rate, log_rate[::-1], np.log(self.lux[peak:])[::-1]))


def load_rate_curves(path: str | Path = BACKGROUND_RATES) -> dict[str, RateCurve]:
    """The shipped table's curve per bias profile."""
    doc = json.loads(Path(path).read_text())
    return {
        name: RateCurve(np.asarray(p["lux"], dtype=np.float64), np.asarray(p["rate_hz"], dtype=np.float64), float(p["dark_hz"]))
        for name, p in doc["profiles"].items()
    }


@dataclass(frozen=True)
class TileGrid:
    """The sensor cut into ``tile_px`` squares (the last row and column may be smaller)."""

    width: int
    height: int
    tile_px: int = TILE_PX

    @property
    def shape(self) -> tuple[int, int]:
        return -(-self.height // self.tile_px), -(-self.width // self.tile_px)

    def areas(self) -> np.ndarray:
        """Pixels per tile, [rows, cols]."""
        rows = np.minimum(self.tile_px, self.height - np.arange(self.shape[0]) * self.tile_px)
        cols = np.minimum(self.tile_px, self.width - np.arange(self.shape[1]) * self.tile_px)
        return np.outer(rows, cols)

    def counts(self, events: Events, stride: int = 1) -> np.ndarray:
        """Events per tile ([rows, cols]); with ``stride`` every stride-th event, scaled back up."""
        picked = events[::stride] if stride > 1 else events
        rows, cols = self.shape
        index = (picked["y"].astype(np.int64) // self.tile_px) * cols + picked["x"].astype(np.int64) // self.tile_px
        return np.bincount(index, minlength=rows * cols).reshape(rows, cols) * stride

    def touching(self, rect: tuple[int, int, int, int]) -> np.ndarray:
        """Tiles that share any pixel with ``rect``."""
        x0, y0, w, h = rect
        ys = np.arange(self.shape[0]) * self.tile_px
        xs = np.arange(self.shape[1]) * self.tile_px
        return np.outer((ys < y0 + h) & (ys + self.tile_px > y0), (xs < x0 + w) & (xs + self.tile_px > x0))


def usable_tiles(grid: TileGrid, excluded: np.ndarray | None) -> np.ndarray:
    """Tiles whose events tell the background: all but ``excluded`` (those the gaze window touched:
    the page being read). Too few of them give no estimate (``background_rate_hz``)."""
    return np.ones(grid.shape, dtype=bool) if excluded is None else ~excluded


def poisson_mean_of_quantile(count: float, z: float) -> float:
    """The mean of a Poisson count whose quantile at the standard normal's ``z`` is ``count`` (the
    normal approximation, mean + z sqrt(mean) = count, solved for the mean)."""
    root = (-z + math.sqrt(z * z + 4.0 * max(count, 0.0))) / 2.0
    return root * root


def background_rate_hz(counts: np.ndarray, areas: np.ndarray, usable: np.ndarray, seconds: float,
                       quantile: float = STILL_QUANTILE, min_tiles: int = MIN_TILES, stride: int = 1) -> float | None:
    """The still scene's events per pixel and second: the ``quantile`` of the usable tiles' rates, as
    the mean of the Poisson count of a typical tile that has it at that quantile (``counts`` made of
    every ``stride``-th event scaled back up; None with fewer than ``min_tiles`` tiles or no time)."""
    if seconds <= 0 or int(usable.sum()) < min_tiles:
        return None
    rates = counts[usable] / (areas[usable] * seconds)
    scale = float(np.median(areas[usable])) * seconds / stride  # a typical tile's events counted per unit of rate
    z = float(NormalDist().inv_cdf(quantile))
    return poisson_mean_of_quantile(float(np.quantile(rates, quantile)) * scale, z) / scale


@dataclass(frozen=True)
class ProfileRule:
    """When the sensor switches: into ``dark`` below ``dark_below_lux``, back to ``factory`` above
    ``bright_above_lux``, never sooner than ``min_dwell_s`` after the last switch."""

    dark_below_lux: float = 15.0
    bright_above_lux: float = 25.0
    min_dwell_s: float = 10.0


@dataclass(frozen=True)
class ProfileState:
    profile: str  # the bias profile chosen
    since_s: float = -math.inf  # when it was chosen (event time)


def next_profile(state: ProfileState, lux: float, t_s: float, rule: ProfileRule) -> ProfileState:
    """The profile after an estimate of ``lux`` at ``t_s``: the same state unless the light crossed
    the threshold away from the current profile and the last switch is ``min_dwell_s`` old."""
    if t_s - state.since_s < rule.min_dwell_s:
        return state
    if state.profile != DARK and lux < rule.dark_below_lux:
        return ProfileState(DARK, t_s)
    if state.profile == DARK and lux > rule.bright_above_lux:
        return ProfileState(FACTORY, t_s)
    return state


def profile_sequence(lux: np.ndarray, t_s: np.ndarray, rule: ProfileRule, start: ProfileState = ProfileState(FACTORY)) -> list[str]:
    """The profile after each of a run of estimates (``lux`` at times ``t_s``): what a controller following
    the rule would run. The estimates come once per slice of event time, a handful per second."""
    state, out = start, []
    for value, t in zip(np.asarray(lux, dtype=np.float64).tolist(), np.asarray(t_s, dtype=np.float64).tolist(), strict=True):
        state = next_profile(state, value, t, rule)
        out.append(state.profile)
    return out
