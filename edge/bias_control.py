"""The dark profile on the glasses: the light level read from the event stream, the EVK4's biases switched.

:class:`BiasController` sits on the reader thread (``Pipeline.sink`` hands it every chunk): it counts
events per tile, and once per ``[sensor] estimate_s`` of event time reads the light at the page from
the background rate on the curve of the profile the sensor runs (``edge/light.py``), then applies
the hysteresis rule. The rate is read per ``PART_S`` of the slice and the slice's estimate is its
stillest part's (the lowest rate): a head moving over a page that fills the view sweeps text edges
(and dark ink) across nearly every tile in a second, seldom in every quarter of one. On a switch it
writes the new profile's biases through the source's own ``set_biases`` (the EVK4 driver), logs one
line with the estimate, counts it (``bias_switches``) and leaves the next ``settle_s`` of events out
of the count (the pixels settle after a bias write). The stream's first ``settle_s`` are left out
too: a sensor that starts streaming settles as after a bias write (its first events read a lit page
as dark: docs/sensor_model.md), and until the first estimate the controller wants
the whole sensor until one part of the slice is read, rather than waiting
``probe_every_s``: the first estimate comes within the session's first seconds even when a ROI
follows the gaze.
``[sensor] lux`` replaces the estimate by a configured light level (decided once, at the start).

A source that cannot change its biases (a replayed recording) gets the controller in advisory mode:
it reads the light on the recording's own profile (``meta.json`` ``biases``), logs and counts what it
would do, and changes nothing. A recording that does not state its biases gives no estimate.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from darkread.core.errors import DarkreadError
from darkread.edge.config import SensorConfig
from darkread.edge.events import Events
from darkread.edge.light import (
    ProfileRule,
    ProfileState,
    RateCurve,
    TileGrid,
    background_rate_hz,
    load_rate_curves,
    next_profile,
    usable_tiles,
)
from darkread.edge.sources.evk4.bias_profiles import BIAS_PROFILES, FACTORY, profile_offsets
from darkread.edge.telemetry import EdgeMetrics

logger = logging.getLogger(__name__)
MIN_READ_SHARE = 0.25  # a part read whole for less of its time than this (a ROI the rest) gives no rate
PART_S = 0.25  # the background is read per this much of a slice, the slice's estimate its stillest part's
# (``[sensor] probe_s`` is held to at least this share of ``estimate_s``: edge/config.py)


def _since_s(start_us: int | None, t_us: int) -> float:
    """Seconds from ``start_us`` (None: not started, none) to ``t_us`` (0 is an event time like any other)."""
    return 0.0 if start_us is None else (t_us - start_us) / 1e6


def profile_named(offsets: dict[str, int] | None) -> str | None:
    """The name of the bias profile whose offsets these are (None: no offsets, or a profile of its own)."""
    if offsets is None:
        return None
    full = {name: int(offsets.get(name, 0)) for name in profile_offsets(FACTORY)}
    return next((name for name in BIAS_PROFILES if profile_offsets(name) == full), None)


class BiasController:
    """Chooses the sensor's bias profile from the light; ``profile`` is the one the source runs now
    (None: unknown, so the light cannot be read from its events)."""

    def __init__(self, config: SensorConfig, source: Any, metrics: EdgeMetrics, profile: str | None,
                 curves: dict[str, RateCurve] | None = None) -> None:
        self.config = config
        self.rule = ProfileRule(config.dark_below_lux, config.bright_above_lux, config.min_dwell_s)
        self.source = source
        self.metrics = metrics
        self.grid = TileGrid(int(source.width), int(source.height))
        self._areas = self.grid.areas()
        self._set_biases: Callable[..., None] | None = getattr(source, "set_biases", None)
        self.advisory = self._set_biases is None
        self.active = profile  # what the sensor runs
        self.state = ProfileState(profile or FACTORY)  # what the rule chose (advisory: what the sensor would run)
        self.curves = load_rate_curves() if curves is None else curves
        self.lux: float | None = None
        self._counts = np.zeros(self.grid.shape, dtype=np.int64)  # this part's
        self._touched = np.zeros(self.grid.shape, dtype=bool)  # tiles the gaze window covered in this part
        self._part_read_s = 0.0  # how much of this part the sensor was read whole (not through a ROI) ...
        self._read_s = 0.0  # ... and of this slice
        self._part_start: int | None = None
        self._rates: list[float] = []  # the slice's parts' background rates
        self._covered_to: int | None = None  # the slice's time accounted for so far
        self._light_read_at: int | None = None  # event time of the last estimate (or of the first event)
        self._probing = False  # the whole sensor is wanted for a light reading (``wants_whole``)
        self._slice_start: int | None = None
        self._settle_until: int | None = None
        self._started = False  # the first event came (the sensor's start settles as a bias write does)
        self._starting = False  # no light read yet: the whole sensor wanted until a part of the slice is read
        self._estimating = config.lux <= 0 and profile in self.curves

    def begin(self) -> None:
        """Before the first event: a configured light level decides now; say what the controller will do."""
        mode = "advisory (the source cannot change its biases)" if self.advisory else "switching the sensor's biases"
        if self.config.lux > 0:
            logger.info("light %.3g lux (configured), %s", self.config.lux, mode)
            self._decide(self.config.lux, 0.0, None)
        elif self.active is None:
            logger.info("the source does not state its bias profile: no light estimate, biases left as they are")
        elif self.active not in self.curves:
            logger.info("no background curve for bias profile %s: no light estimate", self.active)
        else:
            logger.info("light estimated from the background events on the %s profile every %g s, %s",
                        self.active, self.config.estimate_s, mode)
        self.metrics.set_light(self.lux, self.state.profile if self.active is not None else "", self.advisory)

    def push(self, events: Events, gaze_window: tuple[int, int, int, int] | None) -> None:
        """Reader thread: one chunk of events (time-sorted), with the gaze window at the time."""
        if not self._estimating or events.shape[0] == 0:
            return
        t = events["t"]
        if not self._started:
            self._started = True
            if self.config.settle_s > 0:
                self._settle_until = int(t[0]) + int(self.config.settle_s * 1e6)
        if self._settle_until is not None:
            if int(t[-1]) < self._settle_until:
                return
            events = events[int(np.searchsorted(t, self._settle_until)):]
            self._slice_start, self._settle_until = int(events["t"][0]), None
            self._covered_to = self._part_start = self._slice_start
        if self._slice_start is None:
            self._slice_start = self._covered_to = self._part_start = int(events["t"][0])
        t_last = int(events["t"][-1])
        if self._light_read_at is None:
            self._light_read_at = t_last
        if self._whole(getattr(self.source, "roi", None)):
            self._counts += self.grid.counts(events, self.config.stride)
            read = _since_s(self._covered_to, t_last)
            self._read_s += read
            self._part_read_s += read
            if gaze_window is not None:
                self._touched |= self.grid.touching(gaze_window)
        elif self._read_s == 0.0:  # nothing read whole yet: the slice begins when the sensor is whole again
            self._slice_start = self._part_start = t_last
        self._covered_to = t_last
        self._probe(t_last)
        if _since_s(self._part_start, t_last) >= PART_S:
            self._end_part(t_last)
        if t_last - self._slice_start >= self.config.estimate_s * 1e6:
            self._estimate(t_last)

    def wants_whole(self) -> bool:
        """Whether the sensor should deliver all its pixels now, for a light reading (any thread)."""
        return self._probing or self._starting

    def _probe(self, t_last: int) -> None:
        """Through a ROI the light goes unread: once none was read for ``probe_every_s``, ask for the
        whole sensor until ``probe_s`` of it is counted (the slice then ends with an estimate). Before
        the first estimate (the session's start) the whole sensor is wanted until one part of the
        slice is read (``PART_S``: its whole length where the session's first whole-sensor moments
        end within it; a part read whole for less is read while the sensor still settles)."""
        every = self.config.probe_every_s
        # no light read yet: the whole sensor until one part is read (from the state each time, so it
        # ends with the first estimate however the part and the slice end)
        self._starting = every > 0 and self.lux is None and not self._rates
        if self._probing:
            if self._read_s >= self.config.probe_s:
                self._probing = False
        elif not self._starting and every > 0 and self._light_read_at is not None and t_last - self._light_read_at >= every * 1e6:
            self._probing = True
            self._light_read_at = t_last  # (asked once per period, whether or not the source obliges)
            logger.debug("no light read for %g s: the whole sensor for %g s", every, self.config.probe_s)

    def _whole(self, readout: tuple[int, int, int, int] | None) -> bool:
        """Whether the sensor delivers all its pixels. Through a ROI it delivers the page around the
        gaze only, whose text edges a moving head makes fire at any light (read as background they make
        a lit page read dark; docs/sensor_model.md): those chunks are not counted, and a slice read mostly through
        the ROI gives no estimate; the light is read again whenever the sensor is whole (the
        session's start, walking, the gyroscope not trusted)."""
        return readout is None or tuple(readout) == (0, 0, self.grid.width, self.grid.height)

    def _end_part(self, t_last: int) -> None:
        """A part of the slice ends: its background rate, if it was read whole for long enough."""
        seconds = _since_s(self._part_start, t_last)
        if self._part_read_s >= MIN_READ_SHARE * seconds:
            rate = background_rate_hz(self._counts, self._areas, usable_tiles(self.grid, self._touched), self._part_read_s,
                                      stride=self.config.stride)
            if rate is not None:
                self._rates.append(rate)
        self._counts[:] = 0
        self._touched[:] = False
        self._part_read_s = 0.0
        self._part_start = t_last

    def _estimate(self, t_last: int) -> None:
        if _since_s(self._part_start, t_last) >= PART_S / 2:  # the slice's last part, if not too short
            self._end_part(t_last)
        rate = min(self._rates) if self._rates else None
        if rate is not None:
            self._light_read_at = t_last
        self._counts[:] = 0
        self._touched[:] = False
        self._read_s = self._part_read_s = 0.0
        self._rates = []
        self._slice_start = self._part_start = t_last
        if rate is None or self.active is None:
            return
        lux = float(self.curves[self.active].lux_of(rate))
        self._decide(lux, t_last / 1e6, rate)
        self.metrics.set_light(self.lux, self.state.profile, self.advisory)

    def _decide(self, lux: float, t_s: float, rate: float | None) -> None:
        self.lux = lux
        chosen = next_profile(self.state, lux, t_s, self.rule)
        if chosen.profile == self.state.profile:
            self.state = chosen
            return
        seen = f"{rate:.3g} background events per pixel and s on the {self.active} profile" if rate is not None else "configured"
        if self.advisory:
            logger.info("light %.3g lux (%s): would switch the biases %s -> %s (a replay cannot change its biases)",
                        lux, seen, self.state.profile, chosen.profile)
            self.state = chosen
            self.metrics.add("bias_switches")
            return
        assert self._set_biases is not None
        try:
            self._set_biases(**profile_offsets(chosen.profile))
        except DarkreadError as exc:  # the camera refused: stay, and try again only after the dwell time
            logger.warning("light %.3g lux (%s): switching the biases to %s failed: %s", lux, seen, chosen.profile, exc)
            self.state = ProfileState(self.state.profile, t_s)
            return
        logger.info("light %.3g lux (%s): biases switched %s -> %s", lux, seen, self.state.profile, chosen.profile)
        self.active, self.state = chosen.profile, chosen
        self.metrics.add("bias_switches")
        self._estimating = self.config.lux <= 0 and self.active in self.curves
        self._counts[:] = 0
        self._touched[:] = False
        self._rates = []
        self._read_s = self._part_read_s = 0.0
        self._settle_until = int(t_s * 1e6 + self.config.settle_s * 1e6)
