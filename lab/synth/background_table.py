"""The table the glasses read the light level from: background events per pixel vs lux, per bias profile.

The edge (``edge/light.py``) estimates the light from the background rate of the still parts of the
scene and may not import the simulator, so the grounded model's curve is shipped to it as data:
``darkread synth background-table`` runs the central grounded sensor (``sensor_evidence.central_params``)
under each bias profile of ``edge/sources/evk4/bias_profiles.py`` on a still page of paper
(reflectance ``PAPER_REFLECTANCE``, the simulator's own fill of the unsimulated sensor area) at each
lux and writes ``edge/sources/evk4/background_rates.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from darkread.edge.sources.evk4.bias_profiles import BIAS_PROFILES
from darkread.lab.synth.sensor_evidence import central_params
from darkread.models.synth.biases import apply_profile
from darkread.models.synth.sensor import PAPER_REFLECTANCE, background_rate_curve

TABLE_LUX = tuple(float(v) for v in np.round(np.geomspace(0.5, 200.0, 22), 3))


def background_table(*, pixels: int = 512, seconds: float = 10.0, lux: tuple[float, ...] = TABLE_LUX) -> dict[str, Any]:
    """The document ``background_rates.json`` holds: per profile, the rate at each lux and in the dark."""
    levels = np.array((0.0, *lux)) * PAPER_REFLECTANCE
    profiles = {}
    for name in BIAS_PROFILES:
        params = apply_profile(central_params(), name)
        rates = background_rate_curve(params, levels, pixels=pixels, seconds=seconds)
        profiles[name] = {"dark_hz": round(float(rates[0]), 5), "lux": list(lux), "rate_hz": [round(float(r), 5) for r in rates[1:]]}
    return {
        "what": "background events (ON + OFF) per pixel and second of a still page at each lux at the page, "
                "central grounded sensor (docs/sensor_model.md) under each bias profile",
        "made_by": f"darkread synth background-table --pixels {pixels} --seconds {seconds:g}",
        "reflectance": PAPER_REFLECTANCE,
        "profiles": profiles,
    }


def write_background_table(out: str | Path, **kwargs: Any) -> Path:
    path = Path(out)
    path.write_text(json.dumps(background_table(**kwargs), indent=1) + "\n")
    return path
