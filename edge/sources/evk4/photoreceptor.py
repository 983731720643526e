"""The IMX636's light on the chip and its photoreceptor's speed: the laws the grounded simulator runs and
``darkread calibrate sensor`` fits, defined once here (docs/sensor_model.md, "Laws").

- Light on the chip of a Lambertian surface: E_chip = E_scene R T / (4 N^2);
- a first-order photoreceptor whose cut-off is linear in the photocurrent below a ceiling:
  f_c = 1 / (1 / (K E) + 1 / f_max), its time constant 1 / (2 pi f_c).
"""

from __future__ import annotations

import math

import numpy as np

LENS_TRANSMISSION = 0.9
DEFAULT_F_NUMBER = 2.4  # the glasses' event-camera lens (12 mm, f/2.4)


def chip_lux(scene_irradiance: np.ndarray | float, f_number: float, transmission: float = LENS_TRANSMISSION) -> np.ndarray | float:
    """Illuminance on the chip of a Lambertian surface lit by ``scene_irradiance`` (lux x reflectance):
    E_chip = E_scene R T / (4 N^2), 3.9 % of the scene's at f/2.4."""
    return scene_irradiance * (transmission / (4.0 * f_number * f_number))


def photoreceptor_cutoff_hz(total_chip_lux: np.ndarray | float, k_hz_per_chip_lux: float, f_max_hz: float) -> np.ndarray | float:
    """First-order photoreceptor cut-off: linear in the photocurrent (``K E``) below a ceiling
    ``f_max``, combined as two time constants in series: 1 / (1 / (K E) + 1 / f_max)."""
    return 1.0 / (1.0 / (k_hz_per_chip_lux * total_chip_lux) + 1.0 / f_max_hz)


def k_from_time_constant(tau_s: float, total_chip_lux: float, f_max_hz: float) -> float:
    """The law inverted: K from a measured time constant at chip illuminance ``total_chip_lux``, the
    ceiling ``f_max`` taken as known. ValueError when the pixel is as fast as the ceiling allows
    (then the light says nothing about K: record the edge in dimmer light)."""
    f_c = 1.0 / (2.0 * math.pi * tau_s)
    slack = 1.0 / f_c - 1.0 / f_max_hz
    if slack <= 0:
        raise ValueError(
            f"a time constant of {tau_s * 1e6:.0f} us is at the photoreceptor's ceiling (f_max {f_max_hz:g} Hz): "
            "the edge was too bright to measure K; record it in dimmer light"
        )
    return 1.0 / (total_chip_lux * slack)


F_MAX_ASSUMED_HZ = 5400.0  # the ceiling where it is not measured: the log centre of NIST's 25-35 us floor
