"""A second, independent event simulator: H-ESIM (``hesim-3d`` 0.1.0, its Sony IMX636 preset) on our scene.

Our evaluation and our training data come from one sensor model (``sensor.py``); a gain that only
exists on that model should show up when the same scenes are turned into events by another one.
Everything of a recording stays ours (page, scene, head motion, scanpath, gaze rows, calibration,
truth files, the EVT 3.0 writer); only the step "rendered light -> events" is hesim-3d's
``HESIMEventSimulator.simulate_interval(I0, I1, t0_us, t1_us)``, called on the same region our
simulator simulates, at the same time steps. Its scene renderer and asset downloader are never used.

What H-ESIM does per interval (``hesim3d/sensor/hesim_backend.py``), with the IMX636 preset's
betas b = (1, 1, 0.005, 0.04, 0.004, 0), threshold 0.15, refractory 3 us, dark 0.01 / 0.008 Hz:

- log response ``V = ln(b1 I + b2)`` of a linear intensity I (1 = the preset's full scale; b2 is a
  dark offset of 1/200 of it), signal ``S = V(I1) - reference``;
- noise as a log-voltage sd ``sigma(Ic) = sqrt(2 ((b3 Ic)^2 + b4^2)) / (b1 Ic + b2)`` at the
  interval's mean intensity: ~0.06 on bright pixels, ~1 near the dark offset;
- an ON event with probability ``Q((theta - S) / sigma)`` when ``S > 0.3 theta`` (OFF mirrored),
  plus dark events at the preset's rates; at most one event per pixel and interval, **stamped at the
  interval's end** (no per-pixel timestamps inside it); a fired pixel's reference jumps to V(I1)
  (no residual kept); the refractory period masks pixels that fired less than 3 us before.

So the step is part of its model: a pixel crossing several thresholds within one step gives one
event, and every timestamp falls on a step end. We call it at the preset's own rate, ``evs_fps`` =
1 kHz (``STEP_US`` = 1 ms), not at our own 2-8 kHz step (``session.choose_dt_us``, < 0.5 px of
image motion per step): on one CPU core a step of a 100 k-pixel region costs ~12 ms, so our rate
would cost 25-100 s per simulated second. With head motion the image then moves up to a few pixels
per step, and timestamps have 1 ms resolution.

Light: our scene gives ``E = lux * reflectance`` per pixel (illuminance at the page times the
paper's or ink's reflectance). A Lambertian page seen through the glasses' lens puts
``E_sensor = E * T / (4 N^2)`` on the sensor (camera equation; f-number ``N = 2``, transmission
``T = 0.9``: both assumptions). The preset's full scale is anchored by its dark offset: a pixel
whose photocurrent equals the dark current (``b1 I = b2``) sits at the IMX636's low-light cut-off,
0.08 lux at the sensor (Sony/Prophesee datasheet figure). Hence
``I = E_sensor * b2 / 0.08 lux = E * 0.0035`` per lux: paper (reflectance 0.85) at 100 lux is
I = 0.30, at 5 lux 0.015 (3x the dark offset); the dark current equals the photocurrent at
E = 1.4 lux, inside our own model's dark floor of 0.5-3 lux (not tuned to match it). Above ~330 lux
paper exceeds I = 1; the log model is used unclamped there (no pixel saturates in a log sensor).

Only the simulated region runs through H-ESIM; the rest of the sensor gets H-ESIM's own dark events
(at its rates, stamped at step ends) drawn in numpy, as the rest of a static uniform scene would
produce nothing else in its model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, empty_events
from darkread.models.synth.camera import SENSOR_WH
from darkread.models.synth.sensor import concat_events

HESIM_PACKAGE = "hesim-3d"
HESIM_VERSION = "0.1.0"
HESIM_PRESET = "sony_imx636"
F_NUMBER = 2.0  # the glasses' event-camera lens (assumption)
LENS_TRANSMISSION = 0.9  # (assumption)
LOW_LIGHT_CUTOFF_SENSOR_LUX = 0.08  # IMX636 low-light cut-off, illuminance at the sensor (datasheet figure)
STEP_US = 1000.0  # H-ESIM's interval: the preset's evs_fps (see above)
WARM_UP_US = 30_000  # simulated before t = 0 and dropped: the references start exactly at the first image
INSTALL_HINT = ("install it with `make hesim` (pip install --no-deps hesim-3d==0.1.0 plus the `hesim` extra: "
                "it declares opencv-python, which must not sit beside our opencv-contrib-python-headless)")


class HesimUnavailable(RuntimeError):
    """hesim-3d (or torch) is not installed."""


def hesim_missing() -> str | None:
    """Why the second simulator cannot run here (None when it can)."""
    try:
        import hesim3d  # noqa: F401  # imported only to learn whether it loads (torch, h5py, mcap, its compiled core)
    except Exception as exc:  # any import failure means "not usable", said in one line
        return f"hesim-3d is not usable ({type(exc).__name__}: {exc}); {INSTALL_HINT}"
    return None


def load_config() -> Any:
    """hesim-3d's IMX636 ``SensorConfig`` (read from the preset file shipped in its wheel)."""
    reason = hesim_missing()
    if reason:
        raise HesimUnavailable(reason)
    from hesim3d.sensor.config import SensorConfig

    return SensorConfig.from_preset(HESIM_PRESET)


def intensity_per_lux(config: Any) -> float:
    """H-ESIM intensity per lux of ``lux * reflectance`` at the page (see the module docstring)."""
    b2 = float(np.asarray(config.evs_betas, dtype=np.float64)[..., 2].mean())
    sensor_per_page = LENS_TRANSMISSION / (4.0 * F_NUMBER**2)
    return sensor_per_page * b2 / LOW_LIGHT_CUTOFF_SENSOR_LUX


@dataclass
class HesimRegion:
    """One rectangle of sensor pixels driven by H-ESIM; events come out in full-sensor coordinates."""

    simulator: Any  # hesim3d HESIMEventSimulator
    origin: tuple[int, int]
    scale: float  # intensity per lux at the page
    previous: Any = None  # torch tensor: the last intensity image
    t_prev_us: int = 0

    @classmethod
    def create(cls, config: Any, origin: tuple[int, int], seed: int) -> HesimRegion:
        from hesim3d.sensor.hesim_backend import HESIMEventSimulator

        sim = HESIMEventSimulator(config, device="cpu")
        sim.rng.manual_seed(int(seed))  # its own generator (fixed at 9527 otherwise): one recording, one stream
        return cls(sim, (int(origin[0]), int(origin[1])), intensity_per_lux(config))

    def start(self, irradiance: np.ndarray, t_us: int) -> None:
        """The first image: the references are set from it (no events)."""
        import torch

        h, w = irradiance.shape
        self.simulator.reset_state(h, w)
        self.previous = torch.from_numpy(np.ascontiguousarray(irradiance * np.float32(self.scale), dtype=np.float32))
        self.t_prev_us = int(t_us)

    def step(self, irradiance: np.ndarray, t_us: int) -> np.ndarray:
        """Events between the previous image and ``irradiance`` at ``t_us`` (all stamped ``t_us``)."""
        import torch

        current = torch.from_numpy(np.ascontiguousarray(irradiance * np.float32(self.scale), dtype=np.float32))
        _, raw = self.simulator.simulate_interval(self.previous, current, float(self.t_prev_us), float(t_us))
        self.previous, self.t_prev_us = current, int(t_us)
        return self._events(raw, t_us)

    def _events(self, raw: np.ndarray, t_us: int) -> np.ndarray:
        if raw.size == 0:
            return empty_events()
        ev = np.empty(raw.size, dtype=EVENT_CD_DTYPE)
        ev["x"] = raw["x"] + self.origin[0]
        ev["y"] = raw["y"] + self.origin[1]
        ev["p"] = raw["p"] > 0
        ev["t"] = int(t_us)
        return ev


def step_times_us(seconds: float, dt_us: float) -> np.ndarray:
    """Integer step ends over (0, seconds], ``dt_us`` apart (rounded to the sensor's 1 us)."""
    n = int(math.ceil(seconds * 1e6 / dt_us))
    return np.unique(np.round(np.arange(1, n + 1) * dt_us).astype(np.int64))


def simulate_region(session: Any, region: Any, seconds: float, seed: int, *, progress: bool = False) -> np.ndarray:
    """All H-ESIM events of ``region`` over [0, seconds) s; times in us from the session start."""
    import torch
    from tqdm import tqdm


    config = load_config()
    torch.set_num_threads(1)  # one step is small; the machine's cores go to parallel recordings
    scene = session.scene
    dt_us = STEP_US
    pixels = HesimRegion.create(config, (region.x0, region.y0), seed)
    pixels.start(scene.irradiance(region, -WARM_UP_US * 1e-6), 0)
    for t_us in step_times_us(WARM_UP_US * 1e-6, dt_us):  # settle, events dropped
        pixels.step(scene.irradiance(region, (t_us - WARM_UP_US) * 1e-6), int(t_us))
    chunks = []
    ends = step_times_us(seconds, dt_us)
    for t_us in tqdm(ends, disable=not progress, unit="step", desc="simulating (hesim)", leave=False):
        ev = pixels.step(scene.irradiance(region, t_us * 1e-6), int(t_us) + WARM_UP_US)
        if ev.size:
            ev["t"] -= WARM_UP_US
            chunks.append(ev)
    events = concat_events(chunks)
    return events[events["t"] < int(seconds * 1e6)]


def background_events(
    config: Any, seconds: float, dt_us: float, sensor_wh: tuple[int, int],
    exclude: tuple[int, int, int, int] | None, rng: np.random.Generator,
) -> np.ndarray:
    """H-ESIM's dark events over the sensor outside ``exclude`` = (x0, y0, w, h), at its rates and
    stamped at step ends, as its backend would emit them for a uniform, still scene."""
    width, height = sensor_wh
    rate_on, rate_off = float(config.dark_event_rate_pos), float(config.dark_event_rate_neg)
    n = int(rng.poisson((rate_on + rate_off) * width * height * seconds))
    ends = step_times_us(seconds, dt_us)
    ends = ends[ends < int(seconds * 1e6)]
    if n == 0 or ends.size == 0:
        return empty_events()
    x = rng.integers(0, width, n)
    y = rng.integers(0, height, n)
    keep = np.ones(n, dtype=bool)
    if exclude is not None:
        ex0, ey0, ew, eh = exclude
        keep = ~((x >= ex0) & (x < ex0 + ew) & (y >= ey0) & (y < ey0 + eh))
    ev = np.empty(int(keep.sum()), dtype=EVENT_CD_DTYPE)
    ev["x"], ev["y"] = x[keep], y[keep]
    ev["p"] = rng.random(ev.size) < rate_on / (rate_on + rate_off)
    ev["t"] = ends[rng.integers(0, ends.size, ev.size)]
    return ev[np.argsort(ev["t"], kind="stable")]


def describe(config: Any, dt_us: float) -> dict[str, Any]:
    """What ``meta.json`` records about the second simulator (the sensor that made the events)."""
    return {
        "name": "hesim",
        "package": f"{HESIM_PACKAGE} {HESIM_VERSION}",
        "preset": HESIM_PRESET,
        "event_threshold": float(config.event_threshold),
        "refractory_period_us": float(config.refractory_period_us),
        "evs_betas": np.asarray(config.evs_betas, dtype=float).reshape(-1, 6)[0].tolist(),
        "dark_event_rate_hz": [float(config.dark_event_rate_pos), float(config.dark_event_rate_neg)],
        "step_us": round(float(dt_us), 1),
        "intensity_per_lux": intensity_per_lux(config),
        "light_mapping": (f"I = lux * reflectance * T / (4 N^2) * b2 / {LOW_LIGHT_CUTOFF_SENSOR_LUX} lux "
                          f"(N = {F_NUMBER:g}, T = {LENS_TRANSMISSION:g}: the dark offset b2 at the IMX636's low-light cut-off)"),
        "timestamps": "at the end of each step (H-ESIM emits at most one event per pixel and interval)",
    }


def simulate(spec: Any, session: Any, region: Any, seconds: float, rng: np.random.Generator, *,
             progress: bool = False) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The ``Simulator`` (``models.synth.recording``) of hesim-3d: the region's events by H-ESIM, the
    rest of the sensor's noise by its background model."""
    config = load_config()
    signal = simulate_region(session, region, seconds, int(rng.integers(0, 1 << 62)), progress=progress)
    box = (region.x0, region.y0, region.width, region.height)
    background = background_events(config, seconds, STEP_US, SENSOR_WH, box, rng)
    return signal, background, describe(config, STEP_US)
