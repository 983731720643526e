"""The grounded sensor drawn from a measured sensor profile (``darkread calibrate sensor``) instead of its band.

- **K**: log-uniform within a narrow band around the profile's, exp(+-max(10 %, 2 sd)) (its stated
  relative sd: the edges' spread or the tail fit's statistics); f_max the profile's if it was fitted,
  else drawn over the band.
- **Noise**: the process keeps its law (shot noise through its own band, crossing the thresholds);
  its constants (photo-electrons n, the band's ceiling f_n,max, its slope K_n, the dark current E_dark)
  are fitted so that the process reproduces the profile's background curve, each then drawn within
  +-5 % of the fit. The fit is quick because the process's rate is f_n G(c / sigma) + leak with one
  universal G (time scaled by the noise's bandwidth), tabulated once per process by running the event
  sensor itself over a range of light (``crossing_table``), then a grid search over the constants.
- Thresholds, refractory period, leak and hot pixels: the factory draws. The profile must have been
  measured at factory biases (the bias profiles are applied on top).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from typing import Any

import numpy as np

from darkread.edge.calibrate.sensor_profile import SensorProfile, load_sensor_profile
from darkread.models.synth.sensor import (
    DEFAULT_F_NUMBER,
    F_MAX_BAND_HZ,
    NOISE_FIT,
    GroundedSensorParams,
    _log_uniform,
    background_rate_curve,
    grounded_sensor_params,
)

K_MIN_SPREAD = 0.10  # the K band's half-width (log) at least, whatever the profile's stated sd
NOISE_PROFILE_SPREAD = 1.05
TABLE_THRESHOLD = 0.23
TABLE_LEVELS = np.geomspace(0.01, 300.0, 24)  # scene irradiance of the table's sensor
PRIOR_WEIGHT = 0.02  # a weak pull of each constant towards the published fit (log units squared)


@lru_cache(maxsize=1)
def crossing_table(pixels: int = 48, seconds: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """G: noise events per pixel per noise-bandwidth cycle vs threshold / noise sd, measured with the event
    sensor (factory-like thresholds, no leak) over light levels whose noise spans the range."""
    noise: dict[str, Any] = {**NOISE_FIT, "noise_electrons_per_s": NOISE_FIT["noise_electrons_per_s"] / 16.0}
    params = replace(GroundedSensorParams(lux=1.0), c_on=TABLE_THRESHOLD, c_off=TABLE_THRESHOLD, c_sigma=0.04,
                     refractory_us=150.0, leak_rate_hz=0.0, hot_pixel_fraction=0.0, **noise)  # wider noise: low c / sigma too
    rates = background_rate_curve(params, TABLE_LEVELS, pixels=pixels, seconds=seconds, warmup_s=0.5)
    sd, band = params.noise_sd_and_cutoff(TABLE_LEVELS.astype(np.float32))
    x = TABLE_THRESHOLD / sd.astype(np.float64)
    g = np.maximum(rates, 0.5 / (pixels * seconds)) / band.astype(np.float64)  # an empty level: below half an event
    order = np.argsort(x)
    return x[order], np.log(g[order])


def process_rate(chip: np.ndarray, n: np.ndarray, f_max: np.ndarray, k_n: np.ndarray, e_dark: np.ndarray,
                 leak_hz: float, table: tuple[np.ndarray, np.ndarray], threshold: float = TABLE_THRESHOLD,
                 signal_f_max: float = 5000.0) -> np.ndarray:
    """The noise process's background rate at chip illuminance ``chip`` (broadcast over the constants)."""
    e = chip + e_dark
    ceiling = 1.0 / (1.0 / f_max + 1.0 / signal_f_max)
    band = 1.0 / (1.0 / (k_n * e) + 1.0 / ceiling)
    sd = np.sqrt(math.pi * band / (n * e))
    x, log_g = table
    return band * np.exp(np.interp(threshold / sd, x, log_g, right=-30.0)) + leak_hz


def fit_noise_constants(profile: SensorProfile, table: tuple[np.ndarray, np.ndarray] | None = None,
                        leak_hz: float = 0.06 * 1.38) -> dict[str, float]:
    """The noise constants whose process reproduces the profile's background curve (and dark floor),
    by a grid search in log space with a weak pull towards the published fit."""
    table = table if table is not None else crossing_table()
    chip = np.array([p.chip_lux for p in profile.noise_points] + ([0.0] if profile.dark_floor_hz is not None else []))
    measured = np.array([p.rate_hz for p in profile.noise_points]
                        + ([profile.dark_floor_hz] if profile.dark_floor_hz is not None else []))
    base = NOISE_FIT
    n = base["noise_electrons_per_s"] * np.geomspace(0.1, 10.0, 41)
    f_max = np.geomspace(2.0, 80.0, 31)
    k_n = base["noise_k_hz_per_chip_lux"] * np.geomspace(0.33, 3.0, 9)
    e_dark = base["dark_chip_lux"] * np.geomspace(0.25, 4.0, 9)
    grid = np.meshgrid(n, f_max, k_n, e_dark, indexing="ij")
    shape = grid[0].shape
    cols = [g.reshape(-1, 1) for g in grid]
    model = process_rate(chip[None, :], cols[0], cols[1], cols[2], cols[3], leak_hz, table)
    misfit = ((np.log(model) - np.log(np.maximum(measured, 1e-4))[None, :]) ** 2).sum(axis=1)
    for col, key in zip(cols, ("noise_electrons_per_s", "noise_max_hz", "noise_k_hz_per_chip_lux", "dark_chip_lux"), strict=True):
        misfit = misfit + PRIOR_WEIGHT * np.log(col[:, 0] / base[key]) ** 2
    best = np.unravel_index(int(np.argmin(misfit)), shape)
    return {"noise_electrons_per_s": float(n[best[0]]), "noise_max_hz": float(f_max[best[1]]),
            "noise_k_hz_per_chip_lux": float(k_n[best[2]]), "dark_chip_lux": float(e_dark[best[3]])}


_FITTED: dict[str, dict[str, float]] = {}


def fitted_noise_constants(profile: SensorProfile) -> dict[str, float]:
    """``fit_noise_constants`` once per profile and process."""
    key = repr(profile.to_dict()["noise"])
    if key not in _FITTED:
        _FITTED[key] = fit_noise_constants(profile)
    return _FITTED[key]


@lru_cache(maxsize=8)
def profile_at(path: str) -> SensorProfile:
    """The profile of ``path``, read once per process (CalibrationError: missing or wrong)."""
    return load_sensor_profile(path)


def profile_sensor_params(profile: SensorProfile, rng: np.random.Generator, lux: float,
                          f_number: float = DEFAULT_F_NUMBER) -> GroundedSensorParams:
    """A grounded sensor drawn around the profile (see the module's docstring)."""
    if any(profile.bias_offsets.values()):
        raise ValueError("the sensor profile was measured at non-factory biases "
                         f"({profile.bias_offsets}): calibrate at factory biases; the bias profiles are applied on top")
    base = grounded_sensor_params(rng, lux, f_number)  # thresholds, refractory, leak, hot pixels: the factory draws
    half = max(K_MIN_SPREAD, 2.0 * profile.k_relative_sd)
    k = profile.k_hz_per_chip_lux
    noise: dict[str, Any] = {name: _log_uniform(rng, v / NOISE_PROFILE_SPREAD, v * NOISE_PROFILE_SPREAD)
             for name, v in fitted_noise_constants(profile).items()}
    return replace(
        base,
        k_hz_per_chip_lux=_log_uniform(rng, k * math.exp(-half), k * math.exp(half)),
        f_max_hz=profile.f_max_hz if profile.f_max_fitted else _log_uniform(rng, *F_MAX_BAND_HZ),
        **noise,
    )
