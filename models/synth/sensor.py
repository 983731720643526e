"""ESIM-style event generation with a v2e-style low-light model, vectorised over a pixel region.

Per time step the caller hands in the linear irradiance of every pixel of a fixed region (in lux
at the page, i.e. ``lux * reflectance``). The sensor

1. converts it to log intensity with a dark-current floor (``ln(I + dark_lux)``), which compresses
   contrast in dim light;
2. low-pass filters the log intensity with a first-order photoreceptor whose cut-off scales with
   the pixel's own intensity (v2e): in the dark edges lag and smear;
3. emits one event per contrast-threshold crossing between the previous and the current filtered
   sample, crossing times interpolated linearly, several per pixel and step allowed; the reference
   moves to the crossing level; a crossing within the refractory period after the pixel's last
   *emitted* event is dropped but the reference still advances;
4. lets the reference leak downwards (ON leak events) and adds shot-noise events (Bernoulli per
   pixel and step, more in dim light and on dark pixels) and a few hot pixels.

Per-pixel thresholds, leak rates and hot pixels are drawn once per sensor and stay fixed.

The ``grounded`` regime (:class:`GroundedSensorParams`, docs/sensor_model.md) replaces steps 1, 2
and the shot noise of 4 by laws fitted to published IMX636 measurements: the light on the chip
(E_chip = E_scene R T / (4 N^2)), a photoreceptor whose cut-off is linear in chip illuminance up to
a ceiling, dark current as a floor of that illuminance, and background activity as a process:
photon noise of the photocurrent, low-passed, added to the log signal, crossing the same
thresholds with the same refractory period as the signal.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, replace
from functools import lru_cache

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, empty_events
from darkread.edge.sources.evk4.photoreceptor import (  # the laws, shared with `calibrate sensor`
    DEFAULT_F_NUMBER,
    LENS_TRANSMISSION,
    chip_lux,
    photoreceptor_cutoff_hz,
)


@dataclass(frozen=True)
class SensorParams:
    """Physical parameters of one simulated sensor (randomised per recording or training sample)."""

    lux: float = 100.0
    c_on: float = 0.25  # mean ON contrast threshold (log units)
    c_off: float = 0.25  # mean OFF contrast threshold
    c_sigma: float = 0.04  # per-pixel threshold mismatch (sd), drawn once
    refractory_us: float = 100.0
    cutoff_hz: float = 1000.0  # photoreceptor cut-off at saturation (bright light)
    cutoff_half_lux: float = 40.0  # irradiance at which the cut-off is half of ``cutoff_hz``
    dark_lux: float = 0.8  # dark-current floor of the log response, in lux at the page
    shot_rate_100lux_hz: float = 0.1  # shot-noise events per pixel per second at 100 lux
    shot_lux_exponent: float = 0.8  # shot rate ~ (100 / lux) ** exponent
    leak_rate_hz: float = 0.03  # median leak (ON) rate per pixel
    leak_decades: float = 0.3  # log10 spread of per-pixel leak rates
    hot_pixel_fraction: float = 2e-5  # fraction of pixels that fire often
    hot_rate_hz: float = 200.0

    noise_process = False  # True: background activity comes from a modelled noise signal (grounded)
    highpass_hz = 0.0  # the change detector's high-pass (a field of the grounded model only)

    def log_intensity(self, irradiance: np.ndarray) -> np.ndarray:
        """The photoreceptor's settled log response to ``irradiance`` (lux at the page x reflectance)."""
        return np.log(irradiance + np.float32(self.dark_lux))

    def cutoff_of(self, irradiance: np.ndarray) -> np.ndarray:
        """Photoreceptor cut-off (Hz) per pixel: ``cutoff_hz * I / (I + cutoff_half_lux)`` (v2e)."""
        return np.float32(self.cutoff_hz) * irradiance / (irradiance + np.float32(self.cutoff_half_lux))

    def noise_sd_and_cutoff(self, irradiance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The log-noise process's standard deviation and bandwidth per pixel: only a law with
        ``noise_process`` has one (the standard law's background activity is a rate)."""
        raise NotImplementedError(f"{type(self).__name__} models background activity as a rate, not a process")

    def filter_gain(self, irradiance: np.ndarray, dt_us: float) -> np.ndarray:
        """The photoreceptor low-pass's step gain per pixel, 2 pi f_c dt clipped at 1, in the float32
        order the standard recordings were made with (the suite's events stay bit for bit the same)."""
        gain = np.float32(2.0 * math.pi * self.cutoff_hz * dt_us * 1e-6)
        return np.minimum(gain * irradiance / (irradiance + np.float32(self.cutoff_half_lux)), np.float32(1.0))

    def shot_rate_hz(self) -> float:
        """Mean shot-noise rate per pixel at this illuminance (on paper-bright pixels)."""
        return self.shot_rate_100lux_hz * (100.0 / max(self.lux, 0.1)) ** self.shot_lux_exponent

    def background_rate_hz(self) -> float:
        """Mean noise-event rate per pixel (shot + leak), used to fill the unsimulated sensor area."""
        return self.shot_rate_hz() + self.leak_rate_hz

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def random_sensor_params(rng: np.random.Generator, lux: float) -> SensorParams:
    """Parameters drawn over what real sensors and bias settings vary."""
    c_mean = rng.uniform(0.18, 0.32)
    return SensorParams(
        lux=float(lux),
        c_on=float(c_mean * rng.uniform(0.9, 1.1)),
        c_off=float(c_mean * rng.uniform(0.9, 1.1)),
        c_sigma=float(rng.uniform(0.03, 0.05)),
        refractory_us=float(rng.uniform(20.0, 300.0)),
        cutoff_hz=float(rng.uniform(300.0, 1000.0)),
        cutoff_half_lux=float(rng.uniform(100.0, 400.0)),
        dark_lux=float(rng.uniform(0.5, 3.0)),
        shot_rate_100lux_hz=float(rng.uniform(0.03, 0.1)),
        shot_lux_exponent=float(rng.uniform(0.9, 1.1)),
        leak_rate_hz=float(10 ** rng.uniform(-2.0, -1.0)),
        leak_decades=float(rng.uniform(0.2, 0.5)),
        hot_pixel_fraction=float(rng.uniform(0.0, 5e-5)),
        hot_rate_hz=float(rng.uniform(50.0, 500.0)),
    )


PAPER_REFLECTANCE = 0.85  # what the background rate of the unsimulated sensor area is computed at


@dataclass(frozen=True)
class GroundedSensorParams(SensorParams):
    """A sensor whose photoreceptor and background activity follow published IMX636 measurements.

    Light is converted to chip illuminance through the lens; the dark current adds ``dark_chip_lux``
    to it (the floor of the log response and of the photoreceptor's speed). The signal's cut-off
    follows :func:`photoreceptor_cutoff_hz` with ``k_hz_per_chip_lux`` and ``f_max_hz`` (NIST's
    latencies). Noise is the shot noise of the photocurrent (``noise_electrons_per_s`` photo-electrons
    per second per chip-lux) through a first-order band of the same form, an Ornstein-Uhlenbeck signal
    of variance pi f_n / (n E) and bandwidth f_n = 1 / (1 / (K_n E) + 1 / f_n,max), added to the log
    response; noise events are its threshold crossings (same thresholds, same refractory period).
    The published background curves put the noise band's ceiling far below the signal's
    (docs/sensor_model.md: the two data sets disagree under one first-order stage), so it has its
    own constants, fitted to them (``darkread synth sensor-evidence --fit``). The standard-law fields
    it inherits (``cutoff_hz``, ``cutoff_half_lux``, ``dark_lux``, shot noise) are not used.
    """

    f_number: float = DEFAULT_F_NUMBER
    transmission: float = LENS_TRANSMISSION
    k_hz_per_chip_lux: float = 130.0
    f_max_hz: float = 5000.0
    dark_chip_lux: float = 0.004
    noise_k_hz_per_chip_lux: float = 75.0
    noise_max_hz: float = 12.0
    noise_electrons_per_s: float = 3.6e4
    shot_rate_100lux_hz: float = 0.0  # no rate-based shot noise: the noise process makes it
    highpass_hz: float = 0.0  # the change detector's high-pass (bias hpf; factory: off)
    biases: tuple[tuple[str, int], ...] = ()  # the bias offsets from factory it runs with (models/synth/biases.py)

    noise_process = True

    def total_chip_lux(self, irradiance: np.ndarray) -> np.ndarray:
        return np.asarray(chip_lux(irradiance, self.f_number, self.transmission)) + np.float32(self.dark_chip_lux)

    def log_intensity(self, irradiance: np.ndarray) -> np.ndarray:
        return np.log(self.total_chip_lux(irradiance))

    def cutoff_of(self, irradiance: np.ndarray) -> np.ndarray:
        return np.asarray(photoreceptor_cutoff_hz(self.total_chip_lux(irradiance), self.k_hz_per_chip_lux, self.f_max_hz))

    def filter_gain(self, irradiance: np.ndarray, dt_us: float) -> np.ndarray:
        return np.minimum(np.float32(2.0 * math.pi * dt_us * 1e-6) * self.cutoff_of(irradiance), np.float32(1.0))

    def noise_sd_and_cutoff(self, irradiance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel: the log-noise standard deviation and its bandwidth (Hz)."""
        e = self.total_chip_lux(irradiance)
        ceiling = 1.0 / (1.0 / self.noise_max_hz + 1.0 / self.f_max_hz)  # the noise passes the signal's ceiling too
        band = np.asarray(photoreceptor_cutoff_hz(e, self.noise_k_hz_per_chip_lux, ceiling))
        return np.sqrt(np.float32(math.pi) * band / (np.float32(self.noise_electrons_per_s) * e)), band

    def background_rate_hz(self) -> float:
        """Noise events per pixel and second on paper at this light: the same pixel model, simulated."""
        return _paper_background_rate_hz(self)

    def to_dict(self) -> dict[str, float]:
        unused = {"cutoff_hz", "cutoff_half_lux", "dark_lux", "shot_rate_100lux_hz", "shot_lux_exponent"}
        doc = {k: v for k, v in asdict(self).items() if k not in unused}
        doc["biases"] = dict(self.biases)
        return {"law": "grounded", **doc}


@lru_cache(maxsize=64)
def _paper_background_rate_hz(params: GroundedSensorParams) -> float:
    return float(background_rate_curve(params, np.array([PAPER_REFLECTANCE * params.lux]), pixels=512, seconds=4.0)[0])


# Attribution (docs/eval, "what each law decides"): a grounded sensor with one of its laws put back to
# the standard model's, at the centre of the standard draws, so the difference between the two models
# splits into what each law does. Head motion is the fourth law; its regimes are models/synth/motion.py's.
STANDARD_LAWS: tuple[str, ...] = ("photoreceptor", "noise", "dark-current")
STANDARD_CENTRAL = SensorParams(cutoff_hz=650.0, cutoff_half_lux=250.0, dark_lux=1.75, shot_rate_100lux_hz=0.065,
                                shot_lux_exponent=1.0)


@dataclass(frozen=True)
class MixedLawSensorParams(GroundedSensorParams):
    """A grounded sensor with the standard model's law for each name in ``standard_laws``:

    * ``photoreceptor``: the cut-off ``cutoff_hz * I / (I + cutoff_half_lux)`` of the light at the page;
    * ``noise``: background activity as a rate (shot noise ~ 1 / lux, thinned on dark pixels), no noise process;
    * ``dark-current``: the standard floor ``dark_lux`` (lux at the page) taken through the lens to the chip.
    """

    standard_laws: tuple[str, ...] = ()

    @property
    def noise_process(self) -> bool:  # type: ignore[override]  # a class constant elsewhere, a law choice here
        return "noise" not in self.standard_laws

    def total_chip_lux(self, irradiance: np.ndarray) -> np.ndarray:
        if "dark-current" not in self.standard_laws:
            return super().total_chip_lux(irradiance)
        lens = float(chip_lux(1.0, self.f_number, self.transmission))
        return (np.asarray(irradiance, np.float32) + np.float32(self.dark_lux)) * np.float32(lens)

    def cutoff_of(self, irradiance: np.ndarray) -> np.ndarray:
        if "photoreceptor" not in self.standard_laws:
            return super().cutoff_of(irradiance)
        return SensorParams.cutoff_of(self, irradiance)

    def background_rate_hz(self) -> float:
        return SensorParams.background_rate_hz(self) if "noise" in self.standard_laws else super().background_rate_hz()

    def to_dict(self) -> dict[str, float]:
        doc = dict(super().to_dict())
        doc["standard_laws"] = list(self.standard_laws)  # type: ignore[assignment]
        for law, fields in (("photoreceptor", ("cutoff_hz", "cutoff_half_lux")), ("dark-current", ("dark_lux",)),
                            ("noise", ("shot_rate_100lux_hz", "shot_lux_exponent"))):
            if law in self.standard_laws:
                doc.update({f: getattr(self, f) for f in fields})
        return doc


def with_standard_laws(params: GroundedSensorParams, laws: tuple[str, ...]) -> GroundedSensorParams:
    """``params`` with the standard model's law (at its draws' centre) for each of ``laws``."""
    unknown = [law for law in laws if law not in STANDARD_LAWS]
    if unknown:
        raise ValueError(f"--standard-law {unknown[0]!r}: use one of {', '.join(STANDARD_LAWS)}")
    if not laws:
        return params
    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    c = STANDARD_CENTRAL
    fields.update(cutoff_hz=c.cutoff_hz, cutoff_half_lux=c.cutoff_half_lux, dark_lux=c.dark_lux,
                  shot_rate_100lux_hz=c.shot_rate_100lux_hz if "noise" in laws else 0.0,
                  shot_lux_exponent=c.shot_lux_exponent, standard_laws=tuple(sorted(laws)))
    return MixedLawSensorParams(**fields)


REGIMES: tuple[str, ...] = ("standard", "shifted", "fast-photoreceptor", "grounded")
FAST_CUTOFF_GAIN = 2.5  # fast-photoreceptor: the cut-off this many times the standard draw's ...
FAST_HALF_LUX_DIVISOR = 5.0  # ... and halved at this many times less light


def shifted_sensor_params(rng: np.random.Generator, lux: float) -> SensorParams:
    """A sensor outside what training saw (the stand-in for a real camera with other biases).

    Training draws thresholds 0.18-0.32 with sd 0.03-0.05, a photoreceptor cut-off of 300-1000 Hz
    halved at 100-400 lux, shot 0.03-0.1 Hz at 100 lux, leak 0.01-0.1 Hz and hot pixels up to 5e-5.
    This regime has higher, asymmetric and more spread thresholds, a longer refractory period, a
    faster photoreceptor in the dark (cut-off 1.5-2.5 kHz halved at 50-80 lux: ~250 Hz at 10 lux,
    nearer the IMX636's "latency < 1 ms at 5 lux" than training's model), 3-5x the shot noise
    rising faster as light falls, a leakier reference and 4-10x the hot pixels.
    """
    c_mean = rng.uniform(0.36, 0.44)
    return SensorParams(
        lux=float(lux),
        c_on=float(c_mean * rng.uniform(0.85, 0.95)),
        c_off=float(c_mean * rng.uniform(1.05, 1.15)),
        c_sigma=float(rng.uniform(0.06, 0.08)),
        refractory_us=float(rng.uniform(400.0, 600.0)),
        cutoff_hz=float(rng.uniform(1500.0, 2500.0)),
        cutoff_half_lux=float(rng.uniform(50.0, 80.0)),
        dark_lux=float(rng.uniform(3.0, 5.0)),
        shot_rate_100lux_hz=float(rng.uniform(0.3, 0.5)),
        shot_lux_exponent=float(rng.uniform(1.15, 1.25)),
        leak_rate_hz=float(rng.uniform(0.2, 0.4)),
        leak_decades=float(rng.uniform(0.5, 0.7)),
        hot_pixel_fraction=float(rng.uniform(2e-4, 5e-4)),
        hot_rate_hz=float(rng.uniform(500.0, 1000.0)),
    )


def fast_photoreceptor_params(rng: np.random.Generator, lux: float) -> SensorParams:
    """The standard draw (the same random numbers, so the same scene and sensor otherwise) with a
    photoreceptor that keeps up in the dark: the cut-off 2.5x and halved at a fifth of the light.

    How fast the IMX636's photoreceptor is in dim light decides whether a moving page's thin strokes
    fire at all. The standard model answers slowly: a paper pixel at 5 lux responds with a time
    constant of 4-50 ms, dark ink far slower. Sony states "latency < 1 ms at 5 lux" without saying
    whether at the scene or at the sensor. Read as scene light, a paper pixel here responds in
    0.4-4.2 ms (1.3 ms at the middle of the draws). No real dim-light recording tells the two apart,
    so the suite can be made under both (``eval make-suite --regime``) to see what that choice decides.
    """
    p = random_sensor_params(rng, lux)
    return replace(p, cutoff_hz=p.cutoff_hz * FAST_CUTOFF_GAIN, cutoff_half_lux=p.cutoff_half_lux / FAST_HALF_LUX_DIVISOR)


# The grounded draws. K: NIST's band (central 130 Hz per chip-lux, plausible 40-400), log-uniform as
# nothing favours a point inside a band a decade wide (its geometric centre is 126). f_max: NIST's
# latency floor of 25-35 us. Thresholds: factory diff_on/off. Noise constants: the fit's central
# values (NOISE_FIT) with the spread that keeps the curve within the published one.
K_BAND_HZ_PER_CHIP_LUX: tuple[float, float] = (40.0, 400.0)
K_CENTRAL_HZ_PER_CHIP_LUX = 130.0
# K fixed by name (``eval make-suite --k``): the band's slow end, the centre NIST's medians give, the fast end
K_NAMED: dict[str, float] = {"slow": K_BAND_HZ_PER_CHIP_LUX[0], "central": K_CENTRAL_HZ_PER_CHIP_LUX,
                             "fast": K_BAND_HZ_PER_CHIP_LUX[1]}
K_LIMITS: tuple[float, float] = (4.0, 4000.0)  # a K outside a decade of the band is a typo, not a sensor
F_MAX_BAND_HZ: tuple[float, float] = (4500.0, 6400.0)
FACTORY_THRESHOLD_BAND: tuple[float, float] = (0.21, 0.25)
NOISE_FIT = {"noise_k_hz_per_chip_lux": 75.0, "noise_max_hz": 12.0, "noise_electrons_per_s": 3.6e4, "dark_chip_lux": 0.004}
NOISE_SPREAD = 1.15  # each noise constant drawn within [fit / spread, fit * spread], log-uniform


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def grounded_sensor_params(rng: np.random.Generator, lux: float, f_number: float = DEFAULT_F_NUMBER) -> GroundedSensorParams:
    """A sensor drawn over the band the published IMX636 measurements leave open (factory biases)."""
    c_mean = rng.uniform(*FACTORY_THRESHOLD_BAND)
    noise = {k: _log_uniform(rng, v / NOISE_SPREAD, v * NOISE_SPREAD) for k, v in NOISE_FIT.items()}
    return GroundedSensorParams(
        lux=float(lux),
        c_on=float(c_mean * rng.uniform(0.95, 1.05)),
        c_off=float(c_mean * rng.uniform(0.95, 1.05)),
        c_sigma=float(rng.uniform(0.03, 0.05)),
        refractory_us=float(rng.uniform(50.0, 300.0)),
        leak_rate_hz=float(10 ** rng.uniform(-1.5, -1.0)),  # part of the published floor at 30 lux
        leak_decades=float(rng.uniform(0.2, 0.5)),
        hot_pixel_fraction=float(rng.uniform(0.0, 5e-5)),
        hot_rate_hz=float(rng.uniform(50.0, 500.0)),
        f_number=float(f_number),
        k_hz_per_chip_lux=_log_uniform(rng, *K_BAND_HZ_PER_CHIP_LUX),
        f_max_hz=_log_uniform(rng, *F_MAX_BAND_HZ),
        noise_k_hz_per_chip_lux=noise["noise_k_hz_per_chip_lux"],
        noise_max_hz=noise["noise_max_hz"],
        noise_electrons_per_s=noise["noise_electrons_per_s"],
        dark_chip_lux=noise["dark_chip_lux"],
    )


def regime_sensor_params(regime: str, rng: np.random.Generator, lux: float, f_number: float = DEFAULT_F_NUMBER) -> SensorParams:
    """Sensor parameters of a regime: ``standard`` (what training saw), ``shifted``,
    ``fast-photoreceptor`` or ``grounded`` (the only one the lens ``f_number`` matters to)."""
    if regime == "grounded":
        return grounded_sensor_params(rng, lux, f_number)
    if regime == "standard":
        return random_sensor_params(rng, lux)
    if regime == "shifted":
        return shifted_sensor_params(rng, lux)
    if regime == "fast-photoreceptor":
        return fast_photoreceptor_params(rng, lux)
    raise ValueError(f"sensor regime {regime!r}: use one of {', '.join(REGIMES)}")


class EventSensor:
    """The pixels of one rectangular sensor region, with their fixed mismatch and running state.

    ``origin`` is the region's top-left pixel on the full sensor; events carry full-sensor
    coordinates. Call :meth:`reset` with the first irradiance image, then :meth:`step` per sample.
    """

    def __init__(
        self, params: SensorParams, shape: tuple[int, int], origin: tuple[int, int], rng: np.random.Generator
    ) -> None:
        self.params = params
        self.shape = (int(shape[0]), int(shape[1]))
        self.origin = (int(origin[0]), int(origin[1]))
        self.rng = rng
        n = self.shape[0] * self.shape[1]
        self.c_on = np.maximum(rng.normal(params.c_on, params.c_sigma, n), 0.01).astype(np.float32)
        self.c_off = np.maximum(rng.normal(params.c_off, params.c_sigma, n), 0.01).astype(np.float32)
        self.leak_per_s = ((params.leak_rate_hz * 10 ** rng.normal(0.0, params.leak_decades, n)) * self.c_on).astype(np.float32)
        n_hot = rng.binomial(n, min(1.0, params.hot_pixel_fraction))
        self.hot_idx = rng.choice(n, size=n_hot, replace=False) if n_hot else np.zeros(0, dtype=np.int64)
        self.hot_rate = rng.uniform(0.3, 1.0, n_hot) * params.hot_rate_hz
        self.ref = np.zeros(n, dtype=np.float32)
        self.lp: np.ndarray = np.zeros(n, dtype=np.float32)
        self.noise = np.zeros(n, dtype=np.float32)  # the noise signal on the log response (grounded)
        self.last_t = np.full(n, -1e18)
        self.t = 0.0
        self._ready = False

    # -- helpers ---------------------------------------------------------------------------------
    def _log(self, irradiance: np.ndarray) -> np.ndarray:
        return self.params.log_intensity(irradiance.reshape(-1).astype(np.float32))

    def level(self) -> np.ndarray:
        """What the change detector compares with its reference: the filtered log signal plus noise."""
        return self.lp + self.noise if self.params.noise_process else self.lp

    def reset(self, irradiance: np.ndarray, t_us: float, *, steady: bool = True) -> None:
        """Start at ``t_us`` with the filter settled on ``irradiance``.

        ``steady`` places each reference at a random level within one threshold of the signal, as
        after a long history of events (no start-up silence); otherwise the first frame sets the
        references exactly (ESIM).
        """
        self.lp = self._log(irradiance)
        if self.params.noise_process:
            sd, _ = self.params.noise_sd_and_cutoff(irradiance.reshape(-1).astype(np.float32))
            self.noise = (sd * self.rng.standard_normal(self.lp.shape[0], dtype=np.float32)).astype(np.float32)
        if steady:
            self.rebase()
        else:
            self.ref = self.level().copy()
        self.last_t = np.full(self.lp.shape[0], -1e18)
        self.t = float(t_us)
        self._ready = True

    def rebase(self) -> None:
        """Redraw the references around the current filtered signal (steady state after a warm-up)."""
        u = self.rng.random(self.lp.shape[0], dtype=np.float32)
        self.ref = self.level() - self.c_on + u * (self.c_on + self.c_off)

    def settle(self, irradiance: np.ndarray, dt_us: float) -> None:
        """Advance the photoreceptor filter (and noise) only, no events, e.g. to warm it up on a moving scene."""
        self._filter(irradiance, dt_us)
        if self.params.noise_process:
            self._advance_noise(irradiance, dt_us)
        self.t += dt_us

    def _filter(self, irradiance: np.ndarray, dt_us: float) -> np.ndarray:
        # first-order low-pass whose cut-off scales with the pixel's light (SensorParams.cutoff_of)
        i = irradiance.reshape(-1).astype(np.float32, copy=False)
        eps = self.params.filter_gain(i, dt_us)
        target = self._log(irradiance)
        self.lp = self.lp + eps * (target - self.lp)
        return target

    def _advance_noise(self, irradiance: np.ndarray, dt_us: float) -> None:
        """The noise signal one step on: an Ornstein-Uhlenbeck process, exact for any step length."""
        sd, cutoff = self.params.noise_sd_and_cutoff(irradiance.reshape(-1).astype(np.float32, copy=False))
        keep = np.exp(np.float32(-2.0 * math.pi * dt_us * 1e-6) * cutoff)
        fresh = self.rng.standard_normal(self.noise.shape[0], dtype=np.float32)
        self.noise = (keep * self.noise + sd * np.sqrt(1.0 - keep * keep) * fresh).astype(np.float32)

    # -- one step --------------------------------------------------------------------------------
    def step(self, irradiance: np.ndarray, dt_us: float) -> np.ndarray:
        """Advance by ``dt_us`` to the new irradiance image; return the events of the step (time-sorted)."""
        if not self._ready:
            raise RuntimeError("EventSensor.step called before reset()")
        t0, t1 = self.t, self.t + dt_us
        l0 = self.level()
        self._filter(irradiance, dt_us)
        if self.params.noise_process:
            self._advance_noise(irradiance, dt_us)
        l1 = self.level()
        self.ref -= self.leak_per_s * np.float32(dt_us * 1e-6)
        highpass = self.params.highpass_hz
        if highpass > 0:  # the reference follows the signal: slow changes fire nothing
            self.ref += (l0 - self.ref) * np.float32(1.0 - math.exp(-2.0 * math.pi * highpass * dt_us * 1e-6))
        signal = self._crossings(l0, l1, t0, dt_us)
        noise = self._noise(irradiance, t0, dt_us)
        self.t = t1
        events = concat_events([signal, noise]) if noise.size else signal
        if events.size > 1:
            events = events[np.argsort(events["t"], kind="stable")]
        return events

    def _crossings(self, l0: np.ndarray, l1: np.ndarray, t0: float, dt_us: float) -> np.ndarray:
        diff = l1 - self.ref
        idx_on = np.flatnonzero(diff >= self.c_on)
        idx_off = np.flatnonzero(-diff >= self.c_off)
        parts = []
        for idx, c_all, sign, pol in ((idx_on, self.c_on, 1.0, 1), (idx_off, self.c_off, -1.0, 0)):
            if idx.size == 0:
                continue
            c = c_all[idx].astype(np.float64)
            n = np.floor(sign * (l1[idx].astype(np.float64) - self.ref[idx]) / c).astype(np.int64)
            parts.append(self._emit(idx, n, c, sign, pol, l0[idx].astype(np.float64), l1[idx].astype(np.float64), t0, dt_us))
        if not parts:
            return empty_events()
        return concat_events(parts)

    def _emit(
        self,
        idx: np.ndarray,
        n: np.ndarray,
        c: np.ndarray,
        sign: float,
        pol: int,
        l0: np.ndarray,
        l1: np.ndarray,
        t0: float,
        dt_us: float,
    ) -> np.ndarray:
        """Events of pixels ``idx`` that cross ``n`` thresholds ``c`` in direction ``sign``.

        Crossings of one pixel within a step are equally spaced in time (linear interpolation), so
        the refractory rule reduces to: the first kept crossing ``k0`` is the first one at least
        ``refractory`` after the last emitted event, then every ``s``-th one.
        """
        ref = self.ref[idx].astype(np.float64)
        slope = (l1 - l0) * sign  # >= 0 for a real crossing; <= 0 when leak alone moved the reference
        with np.errstate(divide="ignore", invalid="ignore"):
            frac_first = np.where(slope > 0, (ref + sign * c - l0) * sign / slope, 0.0)
            spacing = np.where(slope > 0, c / slope * dt_us, 0.0)
        t_first = t0 + np.clip(frac_first, 0.0, 1.0) * dt_us
        refr = self.params.refractory_us
        last = self.last_t[idx]
        if refr > 0:
            with np.errstate(divide="ignore", invalid="ignore"):
                wait = last + refr - t_first
                k0 = np.where(wait <= 0, 1, np.where(spacing > 0, np.ceil(wait / spacing - 1e-9) + 1, n + 1))
                s = np.where(spacing > 0, np.maximum(1, np.ceil(refr / spacing - 1e-9)), n + 1)
            k0 = k0.astype(np.int64)
            s = s.astype(np.int64)
        else:
            k0 = np.ones_like(n)
            s = np.ones_like(n)
        count = np.where(k0 <= n, (n - k0) // np.maximum(s, 1) + 1, 0)
        self.ref[idx] = ref + sign * n * c
        total = int(count.sum())
        if total == 0:
            return empty_events()
        rep = np.repeat(np.arange(idx.size), count)
        j = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        k = k0[rep] + j * s[rep]
        t = np.minimum(t_first[rep] + (k - 1) * spacing[rep], t0 + dt_us)
        has = count > 0
        last_k = k0 + (count - 1) * s
        self.last_t[idx[has]] = np.minimum(t_first + (last_k - 1) * spacing, t0 + dt_us)[has]
        pix = idx[rep]
        return self._events(pix, pol, t)

    def _noise(self, irradiance: np.ndarray, t0: float, dt_us: float) -> np.ndarray:
        """Shot noise by thinning (cost ~ number of noise events, not pixels) plus hot pixels.

        v2e: the darkest pixels are 4x noisier than saturated ones; normalised so paper
        (reflectance ~0.85) fires at ``shot_rate_hz``.
        """
        p = self.params
        flat = irradiance.reshape(-1)
        max_rate = p.shot_rate_hz() / 0.36
        n = int(self.rng.poisson(max_rate * flat.size * dt_us * 1e-6))
        pix = self.rng.integers(0, flat.size, n)
        rel = np.clip(flat[pix] / max(p.lux, 1e-6), 0.0, 1.0)
        pix = pix[self.rng.random(n) < (1.0 - 0.75 * rel)]
        if self.hot_idx.size:
            k = self.rng.poisson(self.hot_rate * dt_us * 1e-6)
            pix = np.concatenate([pix, np.repeat(self.hot_idx, k)])
        if pix.size == 0:
            return empty_events()
        t = t0 + self.rng.random(pix.size) * dt_us
        pol = self.rng.integers(0, 2, pix.size)
        return self._events(pix, pol, t)

    def _events(self, pix: np.ndarray, pol: np.ndarray | int, t: np.ndarray) -> np.ndarray:
        w = self.shape[1]
        ev = np.empty(pix.size, dtype=EVENT_CD_DTYPE)
        ev["x"] = pix % w + self.origin[0]
        ev["y"] = pix // w + self.origin[1]
        ev["p"] = pol
        ev["t"] = np.floor(t).astype(np.int64)
        return ev


def background_rate_curve(
    params: SensorParams, scene_irradiance: np.ndarray, *, pixels: int = 256, seconds: float = 10.0,
    dt_us: float = 500.0, seed: int = 0, warmup_s: float = 1.0,
) -> np.ndarray:
    """Background events (ON + OFF) per pixel and second of a still, uniform scene at each irradiance
    (lux x reflectance): the event sensor itself run on ``pixels`` pixels per level, hot pixels left out
    (they are counted apart), counted after ``warmup_s`` (the references start spread within a
    threshold, not where their last event left them). Cheap enough per recording.
    """
    levels = np.asarray(scene_irradiance, dtype=np.float64).ravel()
    image = np.repeat(levels[:, None], pixels, axis=1).astype(np.float32)
    sensor = EventSensor(replace(params, hot_pixel_fraction=0.0), image.shape, (0, 0), np.random.default_rng(seed))
    sensor.reset(image, 0.0)
    for _ in range(int(round(warmup_s * 1e6 / dt_us))):
        sensor.step(image, dt_us)
    counts = np.zeros(levels.size)
    for _ in range(int(round(seconds * 1e6 / dt_us))):
        events = sensor.step(image, dt_us)
        if events.size:
            counts += np.bincount(events["y"], minlength=levels.size)
    return counts / (pixels * seconds)


def concat_events(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate event arrays keeping ``EVENT_CD_DTYPE`` (np.concatenate drops its padding)."""
    if not parts:
        return empty_events()
    out = np.empty(sum(p.size for p in parts), dtype=EVENT_CD_DTYPE)
    for name in EVENT_CD_DTYPE.names or ():
        np.concatenate([p[name] for p in parts], out=out[name])
    return out


def background_events(
    params: SensorParams,
    t0_us: int,
    t1_us: int,
    sensor_wh: tuple[int, int],
    exclude: tuple[int, int, int, int] | None,
    rng: np.random.Generator,
) -> np.ndarray:
    """Noise events (shot, leak, hot pixels) over the sensor outside ``exclude`` = (x0, y0, w, h).

    The simulated region makes its own noise; this fills the rest so whole-sensor rates are right
    without simulating every pixel.
    """
    width, height = sensor_wh
    duration_s = max(0, t1_us - t0_us) * 1e-6
    area = width * height
    n = int(rng.poisson(params.background_rate_hz() * area * duration_s))
    x = rng.integers(0, width, n)
    y = rng.integers(0, height, n)
    pol = np.where(rng.random(n) < params.leak_rate_hz / max(params.background_rate_hz(), 1e-12), 1, rng.integers(0, 2, n))
    t = rng.integers(t0_us, max(t0_us + 1, t1_us), n)
    n_hot = rng.binomial(area, min(1.0, params.hot_pixel_fraction))
    hot_x = rng.integers(0, width, n_hot)
    hot_y = rng.integers(0, height, n_hot)
    hx, hy, ht, hp = [], [], [], []
    for i in range(n_hot):  # a handful of pixels; their own streams
        k = int(rng.poisson(params.hot_rate_hz * rng.uniform(0.3, 1.0) * duration_s))
        hx.append(np.full(k, hot_x[i]))
        hy.append(np.full(k, hot_y[i]))
        ht.append(rng.integers(t0_us, max(t0_us + 1, t1_us), k))
        hp.append(rng.integers(0, 2, k))
    if n_hot:
        x = np.concatenate([x, *hx])
        y = np.concatenate([y, *hy])
        t = np.concatenate([t, *ht])
        pol = np.concatenate([pol, *hp])
    if exclude is not None:
        ex0, ey0, ew, eh = exclude
        keep = ~((x >= ex0) & (x < ex0 + ew) & (y >= ey0) & (y < ey0 + eh))
        x, y, t, pol = x[keep], y[keep], t[keep], pol[keep]
    ev = np.empty(x.size, dtype=EVENT_CD_DTYPE)
    ev["x"], ev["y"], ev["p"], ev["t"] = x, y, pol, t
    return ev[np.argsort(ev["t"], kind="stable")]
