"""The sensor profile: what ``darkread calibrate sensor`` measured of one EVK4, as versioned JSON.

The simulator's grounded regime draws from it (``darkread.models.synth.sensor_profile``) instead of its
band: ``darkread eval make-suite --sensor-profile``, ``darkread synth recording|dataset --sensor-profile``.
Schema (docs/calibration.md, "Sensor profile"), version 1::

    {"schema": "darkread.sensor_profile", "version": 1,
     "lens_f_number": 2.4, "lens_transmission": 0.9,
     "biases": {"offsets": {"diff_on": 0, ...}},           # from factory, what it was measured at
     "photoreceptor": {"k_hz_per_chip_lux": 131.0,          # f_c = 1 / (1 / (K E_chip) + 1 / f_max)
                       "k_relative_sd": 0.04,               # spread of the edges' estimates (or the fit's)
                       "f_max_hz": 5300.0, "f_max_fitted": false,
                       "edges": [{"recording", "lux", "reflectance", "chip_lux", "time_constant_us", ...}]},
     "noise": {"points": [{"recording", "lux", "reflectance", "scene_irradiance", "chip_lux",
                           "rate_hz", "on_hz", "off_hz", "pixels", "hot_pixels", "seconds"}],
               "dark_floor_hz": 0.26 | null}}               # a lens-capped recording's rate

``noise.points`` is the background curve (ON + OFF per pixel and second vs the card's scene irradiance,
lux x reflectance); between its points it is read log-log (``sensor_fit.noise_rate_at``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from darkread.core.json_file import read_json_file
from darkread.edge.errors import CalibrationError
from darkread.edge.sources.evk4.bias_profiles import check_bias_offsets

SCHEMA = "darkread.sensor_profile"
VERSION = 1


@dataclass(frozen=True)
class NoisePoint:
    recording: str
    lux: float
    reflectance: float
    chip_lux: float  # without the dark current
    rate_hz: float
    on_hz: float
    off_hz: float
    pixels: int
    hot_pixels: int
    seconds: float

    @property
    def scene_irradiance(self) -> float:
        return self.lux * self.reflectance


@dataclass(frozen=True)
class SensorProfile:
    f_number: float
    k_hz_per_chip_lux: float
    k_relative_sd: float
    f_max_hz: float
    f_max_fitted: bool
    noise_points: tuple[NoisePoint, ...]
    dark_floor_hz: float | None = None
    transmission: float = 0.9
    bias_offsets: dict[str, int] = field(default_factory=dict)
    edges: tuple[dict, ...] = ()

    def to_dict(self) -> dict:
        points = [{"recording": p.recording, "lux": p.lux, "reflectance": p.reflectance,
                   "scene_irradiance": round(p.scene_irradiance, 6), "chip_lux": round(p.chip_lux, 6),
                   "rate_hz": round(p.rate_hz, 5), "on_hz": round(p.on_hz, 5), "off_hz": round(p.off_hz, 5),
                   "pixels": p.pixels, "hot_pixels": p.hot_pixels, "seconds": round(p.seconds, 3)}
                  for p in self.noise_points]
        return {
            "schema": SCHEMA,
            "version": VERSION,
            "lens_f_number": self.f_number,
            "lens_transmission": self.transmission,
            "biases": {"offsets": dict(self.bias_offsets)},
            "photoreceptor": {"k_hz_per_chip_lux": round(self.k_hz_per_chip_lux, 3),
                              "k_relative_sd": round(self.k_relative_sd, 4),
                              "f_max_hz": self.f_max_hz, "f_max_fitted": self.f_max_fitted,
                              "edges": list(self.edges)},
            "noise": {"points": points,
                      "dark_floor_hz": None if self.dark_floor_hz is None else round(self.dark_floor_hz, 5)},
        }


def save_sensor_profile(path: str | Path, profile: SensorProfile) -> None:
    Path(path).write_text(json.dumps(profile.to_dict(), indent=1) + "\n", encoding="utf-8")


def _number(doc: dict, key: str, where: str, *, positive: bool = True) -> float:
    value = doc.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CalibrationError(f"{where}: {key} must be a number, got {value!r}")
    if positive and value <= 0:
        raise CalibrationError(f"{where}: {key} must be positive, got {value!r}")
    return float(value)


def sensor_profile_from_dict(doc: object, where: str = "sensor profile") -> SensorProfile:
    """The profile of a parsed JSON document; CalibrationError naming the first thing wrong."""
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise CalibrationError(f"{where}: not a sensor profile (no \"schema\": \"{SCHEMA}\"; made by `darkread calibrate sensor`)")
    if doc.get("version") != VERSION:
        raise CalibrationError(f"{where}: sensor profile version {doc.get('version')!r}; this darkread reads version {VERSION}")
    pr, noise, biases = doc.get("photoreceptor"), doc.get("noise"), doc.get("biases", {})
    if not isinstance(pr, dict) or not isinstance(noise, dict) or not isinstance(biases, dict):
        raise CalibrationError(f"{where}: photoreceptor, noise and biases must be objects")
    offsets = biases.get("offsets", {})
    try:
        check_bias_offsets(offsets)
    except (ValueError, AttributeError) as exc:
        raise CalibrationError(f"{where}: biases: {exc}") from None
    raw_points = noise.get("points")
    if not isinstance(raw_points, list) or not raw_points:
        raise CalibrationError(f"{where}: noise.points must be a non-empty list")
    points = []
    for i, p in enumerate(raw_points):
        at = f"{where}: noise.points[{i}]"
        if not isinstance(p, dict):
            raise CalibrationError(f"{at} must be an object")
        points.append(NoisePoint(str(p.get("recording", "")), _number(p, "lux", at), _number(p, "reflectance", at),
                                 _number(p, "chip_lux", at), _number(p, "rate_hz", at, positive=False),
                                 _number(p, "on_hz", at, positive=False), _number(p, "off_hz", at, positive=False),
                                 int(_number(p, "pixels", at)), int(_number(p, "hot_pixels", at, positive=False)),
                                 _number(p, "seconds", at)))
    floor = noise.get("dark_floor_hz")
    return SensorProfile(
        f_number=_number(doc, "lens_f_number", where),
        transmission=_number(doc, "lens_transmission", where),
        k_hz_per_chip_lux=_number(pr, "k_hz_per_chip_lux", f"{where}: photoreceptor"),
        k_relative_sd=_number(pr, "k_relative_sd", f"{where}: photoreceptor", positive=False),
        f_max_hz=_number(pr, "f_max_hz", f"{where}: photoreceptor"),
        f_max_fitted=bool(pr.get("f_max_fitted", False)),
        noise_points=tuple(points),
        dark_floor_hz=None if floor is None else _number(noise, "dark_floor_hz", f"{where}: noise", positive=False),
        bias_offsets={str(k): int(v) for k, v in offsets.items()},
        edges=tuple(pr.get("edges", [])),
    )


def load_sensor_profile(path: str | Path) -> SensorProfile:
    """Read and check a sensor profile (CalibrationError for a missing, unreadable or wrong file)."""
    doc = read_json_file(path, "sensor profile", error=CalibrationError, missing="make one with `darkread calibrate sensor`")
    return sensor_profile_from_dict(doc, str(path))
