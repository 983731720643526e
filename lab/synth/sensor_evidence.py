"""The grounded sensor model against the published IMX636 measurements it was made from.

Two plots (``darkread synth sensor-evidence``): background activity per pixel vs lux beside the
two published fits to EVK4 recordings, and latency vs chip illuminance beside NIST's points; and
the fit of the noise constants (``--fit``) that puts the first plot's model through the published
curve. The evidence, in the figures the sources give (docs/sensor_model.md cites them):

- Noise2Image (Cao et al., Optica 2025) and Noise2Params (arXiv 2605.16317), factory biases,
  ON + OFF events per pixel and second of a still, uniform scene;
- Chassagnol et al., "Pixel Latency Measurements of Event Cameras" (IEEE TIM 2025): median latency
  of two IMX636 at factory biases.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from darkread.models.synth.sensor import (
    F_MAX_BAND_HZ,
    K_BAND_HZ_PER_CHIP_LUX,
    NOISE_FIT,
    GroundedSensorParams,
    background_rate_curve,
    grounded_sensor_params,
    photoreceptor_cutoff_hz,
)


@dataclass(frozen=True)
class Band:
    """A published value as the interval its sources span."""

    x: float
    lo: float
    hi: float

    @property
    def mid(self) -> float:
        return math.sqrt(self.lo * self.hi)


# Background activity (ON + OFF per pixel, Hz) at scene lux; lux 0 is the dark floor.
PUBLISHED_BACKGROUND: tuple[Band, ...] = (
    Band(0.0, 0.15, 0.5),
    Band(1.0, 1.15, 1.28),
    Band(2.0, 1.25, 1.37),  # "~1.31": the peak's 1.3-1.4 less a little
    Band(5.0, 0.63, 0.99),
    Band(10.0, 0.23, 0.48),
    Band(30.0, 0.07, 0.14),
)
# Median latency (s) at chip lux; the floor is drawn at the brightest point.
NIST_LATENCY: tuple[Band, ...] = (
    Band(2.0, 0.50e-3, 0.70e-3),
    Band(15.0, 0.09e-3, 0.12e-3),
    Band(50.0, 40e-6, 55e-6),
    Band(1000.0, 25e-6, 35e-6),
)
# The published lux is the illuminance of what the camera looks at (a monitor's face, a white card):
# reflectance 1 at the paper's f/2.4 (GroundedSensorParams' default lens).
PUBLISHED_REFLECTANCE = 1.0
FACTORY: dict[str, Any] = dict(c_on=0.23, c_off=0.23, c_sigma=0.04, refractory_us=150.0, leak_rate_hz=0.06, leak_decades=0.35,
               hot_pixel_fraction=0.0)


def central_params(**noise: float) -> GroundedSensorParams:
    """The grounded sensor at the centre of its draws (factory thresholds, central K and noise fit)."""
    changes: dict[str, Any] = {**FACTORY, **NOISE_FIT, **noise}
    return replace(GroundedSensorParams(lux=5.0), **changes)


def model_background(params: GroundedSensorParams, lux: np.ndarray, *, pixels: int = 256, seconds: float = 10.0,
                     seed: int = 0) -> np.ndarray:
    """The model's background Hz per pixel of a still scene of reflectance 1 at each lux."""
    return background_rate_curve(params, np.asarray(lux, dtype=np.float64) * PUBLISHED_REFLECTANCE,
                                 pixels=pixels, seconds=seconds, seed=seed)


def background_misfit(rates: np.ndarray, bands: tuple[Band, ...] = PUBLISHED_BACKGROUND) -> float:
    """Sum of squared log distances of the model's rates from each published interval (0 inside)."""
    total = 0.0
    for rate, band in zip(rates, bands):
        r = max(float(rate), 1e-6)
        total += max(0.0, math.log(band.lo / r), math.log(r / band.hi)) ** 2 + 0.1 * math.log(r / band.mid) ** 2
    return total


def fit_noise(*, pixels: int = 128, seconds: float = 5.0, max_evaluations: int = 80) -> dict[str, float]:
    """The noise constants (NOISE_FIT's keys) that put the central sensor through the published curve."""
    from scipy.optimize import minimize

    keys = tuple(NOISE_FIT)
    lux = np.array([b.x for b in PUBLISHED_BACKGROUND])

    def misfit(logs: np.ndarray) -> float:
        noise = dict(zip(keys, np.exp(logs)))
        return background_misfit(model_background(central_params(**noise), lux, pixels=pixels, seconds=seconds))

    start = np.log([NOISE_FIT[k] for k in keys])
    result = minimize(misfit, start, method="Nelder-Mead",
                      options={"maxfev": max_evaluations, "xatol": 0.02, "fatol": 1e-3})
    return {k: float(f"{v:.4g}") for k, v in zip(keys, np.exp(result.x))}


def latency_s(k_hz_per_chip_lux: float, f_max_hz: float, chip_lux: np.ndarray) -> np.ndarray:
    """The photoreceptor's time constant 1 / (2 pi f_c): NIST's first-order fit equates it with latency."""
    return 1.0 / (2.0 * math.pi * np.asarray(photoreceptor_cutoff_hz(np.asarray(chip_lux, dtype=np.float64), k_hz_per_chip_lux, f_max_hz)))


def background_band(lux: np.ndarray, draws: int, *, pixels: int = 128, seconds: float = 5.0) -> np.ndarray:
    """[draws, len(lux)]: the background curve of grounded sensors drawn over their band (K, thresholds, noise)."""
    rows = []
    for seed in range(draws):
        params = replace(grounded_sensor_params(np.random.default_rng([48, seed]), 5.0), hot_pixel_fraction=0.0)
        rows.append(model_background(params, lux, pixels=pixels, seconds=seconds, seed=seed))
    return np.array(rows)


def evidence_figure(out: str | Path, *, draws: int = 12) -> Path:
    """The two plots of the model against the evidence, side by side, written to ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_n, ax_l) = plt.subplots(1, 2, figsize=(11, 4.2))
    lux = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0])
    shown = np.where(lux == 0, 0.2, lux)  # the dark floor drawn at the left edge
    band = background_band(lux, draws)
    ax_n.fill_between(shown, band.min(axis=0), band.max(axis=0), color="tab:blue", alpha=0.2,
                      label=f"grounded model, {draws} sensors drawn over its band")
    ax_n.plot(shown, model_background(central_params(), lux), color="tab:blue", lw=2, label="grounded model, central draw")
    for b in PUBLISHED_BACKGROUND:
        x = 0.2 if b.x == 0 else b.x
        ax_n.plot([x, x], [b.lo, b.hi], color="black", lw=4, solid_capstyle="butt")
    ax_n.plot([], [], color="black", lw=4, label="Noise2Image / Noise2Params (EVK4, factory biases)")
    ax_n.set_xscale("log")
    ax_n.set_yscale("log")
    ax_n.set_xlabel("scene lux (reflectance 1, f/2.4; the dark floor at 0.2)")
    ax_n.set_ylabel("background events per pixel per s (ON + OFF)")
    ax_n.set_title("background activity of a still scene", fontsize=10)
    ax_n.legend(fontsize=7, loc="lower left")

    chip = np.logspace(-1.5, 3, 200)
    k_lo, k_hi = K_BAND_HZ_PER_CHIP_LUX
    f_lo, f_hi = F_MAX_BAND_HZ
    ax_l.fill_between(chip, latency_s(k_hi, f_hi, chip) * 1e3, latency_s(k_lo, f_lo, chip) * 1e3, color="tab:orange",
                      alpha=0.25, label=f"grounded model, K {k_lo:g}-{k_hi:g} Hz/chip-lux, f_max {f_lo / 1e3:g}-{f_hi / 1e3:g} kHz")
    ax_l.plot(chip, latency_s(130.0, math.sqrt(f_lo * f_hi), chip) * 1e3, color="tab:orange", lw=2, label="K = 130 (central)")
    for b in NIST_LATENCY:
        ax_l.plot([b.x, b.x], [b.lo * 1e3, b.hi * 1e3], color="black", lw=4, solid_capstyle="butt")
    ax_l.plot([], [], color="black", lw=4, label="NIST, two IMX636 (median, factory biases; floor at right)")
    ax_l.set_xscale("log")
    ax_l.set_yscale("log")
    ax_l.set_xlabel("chip lux")
    ax_l.set_ylabel("latency = photoreceptor time constant (ms)")
    ax_l.set_title("photoreceptor speed", fontsize=10)
    ax_l.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
