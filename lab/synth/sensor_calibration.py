"""Simulated ``calibrate sensor`` recordings: what an EVK4 owner records with a lux meter, made by the
grounded simulator at a known K and noise process (``darkread synth sensor-calibration``), and the
check that ``darkread calibrate sensor`` recovers them (``darkread synth sensor-calibration --check``).

Small on purpose: a card is a crop of the sensor (``card_wh`` pixels) seen for a few seconds, the edge a
strip it sweeps across. Each recording is a folder with ``events.raw`` (full-sensor coordinates) and
``meta.json`` stating its light, as a user would, and the simulated sensor (the truth).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from darkread.edge.calibrate.sensor import calibrate_sensor, recordings_in
from darkread.edge.io.raw import write_raw
from darkread.edge.sources.evk4.bias_profiles import profile_offsets
from darkread.lab.synth.sensor_evidence import FACTORY
from darkread.models.synth.biases import apply_profile
from darkread.models.synth.sensor import (
    NOISE_FIT,
    EventSensor,
    GroundedSensorParams,
    background_rate_curve,
    concat_events,
)

SENSOR_WH = (1280, 720)
CARD_REFLECTANCE = 0.8
EDGE_DARK_REFLECTANCE = 0.05
CARD_DT_US = 500.0
EDGE_DT_US = 20.0
WARMUP_S = 0.5


@dataclass(frozen=True)
class CalibrationSpec:
    """What to simulate: the sensor's truth and the recordings' light and size."""

    k_hz_per_chip_lux: float = 130.0
    f_max_hz: float = 5000.0
    card_lux: tuple[float, ...] = (1.0, 3.0, 10.0, 30.0)
    dark: bool = True
    card_seconds: float = 3.0
    card_wh: tuple[int, int] = (32, 32)
    edge_lux: float = 20.0
    edge_speed_px_s: float = 10000.0
    edge_wh: tuple[int, int] = (48, 16)
    edge_tail_taus: float = 12.0  # recorded after the edge has crossed the strip
    f_number: float = 2.4
    bias_profile: str = "factory"
    seed: int = 0


def true_sensor(spec: CalibrationSpec) -> GroundedSensorParams:
    """The simulated sensor: the grounded model's centre (factory thresholds, the noise fit) at the spec's K."""
    params = replace(GroundedSensorParams(lux=spec.edge_lux), **{**FACTORY, **NOISE_FIT}, f_number=spec.f_number,
                     k_hz_per_chip_lux=spec.k_hz_per_chip_lux, f_max_hz=spec.f_max_hz)
    return apply_profile(params, spec.bias_profile)


def _write(folder: Path, events: np.ndarray, block: dict, spec: CalibrationSpec, params: GroundedSensorParams) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    write_raw(folder / "events.raw", events, width=SENSOR_WH[0], height=SENSOR_WH[1])
    meta = {"sensor_calibration": block, "lens_f_number": spec.f_number,
            "biases": {"profile": spec.bias_profile, "offsets": profile_offsets(spec.bias_profile)},
            "simulator": "darkread", "sensor_regime": "grounded", "sensor": params.to_dict()}
    (folder / "meta.json").write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    return folder


def card_events(params: GroundedSensorParams, irradiances: list[float], seconds: float, wh: tuple[int, int],
                seed: int) -> list[np.ndarray]:
    """Still uniform cards (each ``irradiance`` = lux x reflectance) on a ``wh`` crop, after a warm-up:
    one sensor runs all of them side by side (rows of blocks), each returned at the crop's place."""
    w, h = wh
    n = len(irradiances)
    origin = ((SENSOR_WH[0] - w) // 2, (SENSOR_WH[1] - h) // 2)
    image = np.repeat(np.asarray(irradiances, np.float32), h)[:, None] * np.ones((1, w), np.float32)
    sensor = EventSensor(replace(params, hot_pixel_fraction=0.0), (n * h, w), (0, 0), np.random.default_rng(seed))
    sensor.reset(image, 0.0)
    for _ in range(int(WARMUP_S * 1e6 / CARD_DT_US)):
        sensor.step(image, CARD_DT_US)
    events = concat_events([sensor.step(image, CARD_DT_US) for _ in range(int(round(seconds * 1e6 / CARD_DT_US)))])
    events["t"] -= int(WARMUP_S * 1e6)
    out = []
    for i in range(n):
        part = events[(events["y"] >= i * h) & (events["y"] < (i + 1) * h)].copy()
        part["y"] += origin[1] - i * h
        part["x"] += origin[0]
        out.append(part)
    return out


def edge_events(params: GroundedSensorParams, spec: CalibrationSpec, seed: int) -> np.ndarray:
    """A bright edge (``CARD_REFLECTANCE``) sweeping in +x at ``edge_speed_px_s`` over a dark field."""
    w, h = spec.edge_wh
    origin = ((SENSOR_WH[0] - w) // 2, (SENSOR_WH[1] - h) // 2)
    bright, dark = spec.edge_lux * CARD_REFLECTANCE, spec.edge_lux * EDGE_DARK_REFLECTANCE
    sensor = EventSensor(replace(params, hot_pixel_fraction=0.0), (h, w), origin, np.random.default_rng(seed))
    dark_image = np.full((h, w), dark, dtype=np.float32)
    sensor.reset(dark_image, 0.0)
    for _ in range(int(WARMUP_S * 1e6 / CARD_DT_US)):
        sensor.step(dark_image, CARD_DT_US)
    t_start = sensor.t
    cutoff = float(params.cutoff_of(np.array([bright], np.float32))[0])
    tau_s = 1.0 / (2.0 * math.pi * cutoff)
    lead_s = 0.5 * spec.edge_tail_taus * tau_s  # the edge enters after this much still dark field (background)
    seconds = lead_s + w / spec.edge_speed_px_s + spec.edge_tail_taus * tau_s
    columns = np.arange(w, dtype=np.float32)[None, :]
    parts = []
    for i in range(1, int(math.ceil(seconds * 1e6 / EDGE_DT_US)) + 1):
        front = (i * EDGE_DT_US * 1e-6 - lead_s) * spec.edge_speed_px_s  # the edge's position in pixels
        cover = np.clip(front - columns, 0.0, 1.0)
        image = np.broadcast_to(dark + (bright - dark) * cover, (h, w)).astype(np.float32)
        parts.append(sensor.step(image, EDGE_DT_US))
    events = concat_events(parts)
    events["t"] -= int(t_start)
    return events


def write_calibration_recordings(out: str | Path, spec: CalibrationSpec) -> list[Path]:
    """Card recordings at each ``card_lux`` (and a dark one), and an edge recording, under ``out``."""
    out = Path(out)
    params = true_sensor(spec)
    folders = []
    levels = [lux * CARD_REFLECTANCE for lux in spec.card_lux] + ([0.0] if spec.dark else [])
    cards = card_events(params, levels, spec.card_seconds, spec.card_wh, spec.seed * 100 + 1)
    for lux, events in zip(spec.card_lux, cards, strict=False):
        folders.append(_write(out / f"card-{lux:g}lux", events,
                              {"target": "card", "lux": lux, "reflectance": CARD_REFLECTANCE}, spec, params))
    if spec.dark:
        folders.append(_write(out / "dark", cards[-1], {"target": "dark", "lux": 0.0, "reflectance": CARD_REFLECTANCE},
                              spec, params))
    events = edge_events(params, spec, spec.seed * 100 + 50)
    folders.append(_write(out / f"edge-{spec.edge_lux:g}lux", events,
                          {"target": "edge", "lux": spec.edge_lux, "reflectance": CARD_REFLECTANCE,
                           "dark_reflectance": EDGE_DARK_REFLECTANCE}, spec, params))
    return folders


def true_noise_curve(spec: CalibrationSpec, lux: np.ndarray, *, pixels: int = 512, seconds: float = 10.0,
                     seed: int = 7) -> np.ndarray:
    """The simulated sensor's own background curve (ON + OFF per pixel and second) of the card at ``lux``,
    measured apart from the recordings (more pixels, another seed)."""
    return background_rate_curve(true_sensor(spec), np.asarray(lux, np.float64) * CARD_REFLECTANCE,
                                 pixels=pixels, seconds=seconds, seed=seed, warmup_s=WARMUP_S)


def run_check(out: str | Path, specs: list[CalibrationSpec], *, truth_pixels: int = 512, truth_seconds: float = 10.0) -> list[dict]:
    """For each spec: write its recordings under ``out/k<K>``, calibrate them, and compare with the truth
    (K; the noise curve at each card level, measured apart on ``truth_pixels`` pixels)."""
    rows = []
    for spec in specs:
        folder = Path(out) / f"k{spec.k_hz_per_chip_lux:g}"
        write_calibration_recordings(folder, spec)
        profile = calibrate_sensor(recordings_in(folder)).profile
        lux = np.array([p.lux for p in profile.noise_points])
        truth = true_noise_curve(spec, lux, pixels=truth_pixels, seconds=truth_seconds)
        rows.append({"k_true": spec.k_hz_per_chip_lux, "k_fit": profile.k_hz_per_chip_lux,
                     "k_relative_sd": profile.k_relative_sd, "lux": lux.tolist(), "noise_true": truth.tolist(),
                     "noise_fit": [p.rate_hz for p in profile.noise_points], "dark_floor_hz": profile.dark_floor_hz,
                     "bias_profile": spec.bias_profile})
    return rows


def check_table(rows: list[dict]) -> str:
    """The check's rows as a markdown table: K and the noise curve, recovered vs true."""
    lines = ["| K true | K recovered | error | noise at lux: recovered / true Hz (error) |", "|---|---|---|---|"]
    for r in rows:
        noise = ", ".join(f"{lx:g}: {f:.3f} / {t:.3f} ({f / t - 1:+.0%})"
                          for lx, f, t in zip(r["lux"], r["noise_fit"], r["noise_true"], strict=True))
        lines.append(f"| {r['k_true']:g} | {r['k_fit']:.1f} | {r['k_fit'] / r['k_true'] - 1:+.1%} | {noise} |")
    return "\n".join(lines)
