"""``darkread calibrate sensor``: the calibration recordings on disk, and the sensor profile fitted from them.

A calibration recording is a RAW file with what the lux meter said: either a folder holding
``events.raw`` and ``meta.json`` with a ``sensor_calibration`` block (what ``darkread synth
sensor-calibration`` writes)::

    {"sensor_calibration": {"target": "card", "lux": 5.0, "reflectance": 0.8},
     "lens_f_number": 2.4, "biases": {"offsets": {"diff_on": 0, ...}}}

or a RAW file named on the command line with its lux (``--card card5.raw@5``). Targets: ``card`` (a
still blank card filling the view), ``dark`` (the lens capped: the dark-current floor), ``edge`` (a bright
edge, reflectance ``reflectance``, swept once over a dark field, ``dark_reflectance``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darkread.edge.calibrate.sensor_fit import BackgroundRate, EdgeFit, background_rate, edge_time_constant
from darkread.edge.calibrate.sensor_profile import NoisePoint, SensorProfile
from darkread.edge.errors import CalibrationError, RecordingError
from darkread.edge.io.raw import RawData, read_raw
from darkread.edge.sources.evk4.bias_profiles import check_bias_offsets
from darkread.edge.sources.evk4.photoreceptor import (
    DEFAULT_F_NUMBER,
    F_MAX_ASSUMED_HZ,
    LENS_TRANSMISSION,
    chip_lux,
    k_from_time_constant,
)

TARGETS = ("card", "dark", "edge")
CARD_REFLECTANCE = 0.8  # a white card
EDGE_DARK_REFLECTANCE = 0.05  # black card or ink
MIN_CARD_LEVELS = 3
WARMUP_FRACTION = 0.1  # of a card recording left out at its start (at most WARMUP_MAX_S)
WARMUP_MAX_S = 1.0


@dataclass(frozen=True)
class CalibrationRecording:
    name: str
    raw: Path
    target: str
    lux: float
    reflectance: float
    dark_reflectance: float = EDGE_DARK_REFLECTANCE
    f_number: float | None = None  # None: not stated
    bias_offsets: dict[str, int] | None = None


@dataclass
class SensorCalibration:
    """The profile and what each recording gave."""

    profile: SensorProfile
    cards: list[tuple[CalibrationRecording, BackgroundRate]] = field(default_factory=list)
    edges: list[tuple[CalibrationRecording, EdgeFit, float]] = field(default_factory=list)  # with its K


def _float(block: dict, key: str, where: str, default: float | None = None) -> float:
    value = block.get(key, default)
    if value is None:
        raise CalibrationError(f"{where}: no {key} (state it in meta.json's sensor_calibration block, "
                               f"or name the RAW file with --card/--edge FILE@LUX)")
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{where}: {key} must be a number >= 0, got {value!r}")
    return float(value)


def recording_from_folder(folder: Path) -> CalibrationRecording:
    """A recording folder with events.raw and meta.json's ``sensor_calibration`` block."""
    meta_path = folder / "meta.json"
    if not meta_path.is_file():
        raise CalibrationError(f"{folder}: no meta.json stating the light (lux) of this calibration recording")
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except (ValueError, OSError) as exc:
        raise CalibrationError(f"{meta_path}: not readable as JSON ({exc})") from None
    block = meta.get("sensor_calibration") if isinstance(meta, dict) else None
    if not isinstance(block, dict):
        raise CalibrationError(f"{meta_path}: no sensor_calibration block (target, lux, reflectance)")
    target = block.get("target")
    if target not in TARGETS:
        raise CalibrationError(f"{meta_path}: sensor_calibration.target {target!r}: use one of {', '.join(TARGETS)}")
    where = str(meta_path)
    lux = 0.0 if target == "dark" else _float(block, "lux", where)
    biases = meta.get("biases", {})
    offsets = biases.get("offsets") if isinstance(biases, dict) else None
    f_number = meta.get("lens_f_number")
    return CalibrationRecording(
        name=folder.name, raw=folder / "events.raw", target=target, lux=lux,
        reflectance=_float(block, "reflectance", where, CARD_REFLECTANCE if target != "edge" else 0.8),
        dark_reflectance=_float(block, "dark_reflectance", where, EDGE_DARK_REFLECTANCE),
        f_number=None if f_number is None else _float(meta, "lens_f_number", where),
        bias_offsets=None if offsets is None else {str(k): v for k, v in offsets.items()},
    )


def recordings_in(folder: str | Path) -> list[CalibrationRecording]:
    """The calibration recordings of ``folder``: the folder itself, or each sub-folder with an events.raw."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CalibrationError(f"{folder}: no such folder of calibration recordings")
    if (folder / "events.raw").is_file():
        return [recording_from_folder(folder)]
    subs = sorted(d for d in folder.iterdir() if d.is_dir() and (d / "events.raw").is_file())
    if not subs:
        raise CalibrationError(f"{folder}: no calibration recordings (sub-folders with events.raw and meta.json)")
    return [recording_from_folder(d) for d in subs]


def recording_from_argument(target: str, text: str, reflectance: float, dark_reflectance: float) -> CalibrationRecording:
    """``FILE.raw@LUX`` (``FILE.raw`` alone for a dark recording) from the command line."""
    path, sep, lux_text = text.rpartition("@")
    if target == "dark" and not sep:
        path, lux_text = text, "0"
    if not sep and target != "dark":
        raise CalibrationError(f"--{target} {text}: state the light as FILE.raw@LUX (the lux meter's reading at the {target})")
    try:
        lux = float(lux_text)
    except ValueError:
        raise CalibrationError(f"--{target} {text}: {lux_text!r} is not a light level in lux") from None
    if not math.isfinite(lux) or lux < 0 or (target != "dark" and lux == 0):
        raise CalibrationError(f"--{target} {text}: the light must be a positive number of lux")
    raw = Path(path)
    return CalibrationRecording(name=raw.stem, raw=raw, target=target, lux=lux, reflectance=reflectance,
                                dark_reflectance=dark_reflectance)


def _events(rec: CalibrationRecording) -> RawData:
    if not rec.raw.is_file():
        raise CalibrationError(f"{rec.raw}: no such RAW file")
    try:
        return read_raw(rec.raw)
    except (RecordingError, ValueError, OSError) as exc:  # a header or data the decoder refuses
        raise CalibrationError(f"{rec.name}: the RAW file cannot be read ({exc})") from None


def measure_card(rec: CalibrationRecording) -> BackgroundRate:
    data = _events(rec)
    ev = data.events
    if ev.size < 2:
        raise CalibrationError(f"{rec.name}: {ev.size} events: a card recording needs seconds of background activity")
    t = ev["t"].astype(np.int64)
    t_first, t_last = int(t[0]), int(t[-1])
    warmup = min(WARMUP_MAX_S * 1e6, WARMUP_FRACTION * (t_last - t_first))
    return background_rate(ev["x"], ev["y"], ev["p"], t, t_first + warmup, t_last)


def measure_edge(rec: CalibrationRecording) -> EdgeFit:
    data = _events(rec)
    ev = data.events
    try:
        return edge_time_constant(ev["x"], ev["y"], ev["p"], ev["t"].astype(np.int64), int(data.header.width))
    except ValueError as exc:
        raise CalibrationError(f"{rec.name}: {exc}") from None


def _agreed(recordings: list[CalibrationRecording], f_number: float | None, biases: dict[str, int] | None) -> tuple[float, dict[str, int]]:
    """The one f-number and bias setting of all recordings (the command line's if given)."""
    stated_f = {r.f_number for r in recordings if r.f_number is not None}
    if f_number is None:
        if len(stated_f) > 1:
            raise CalibrationError(f"the recordings state different lens f-numbers ({sorted(stated_f)}): calibrate one lens at a time")
        f_number = stated_f.pop() if stated_f else DEFAULT_F_NUMBER
    if not 0.7 <= f_number <= 32:
        raise CalibrationError(f"lens f-number {f_number:g} is outside 0.7..32")
    stated_b = {json.dumps(r.bias_offsets, sort_keys=True) for r in recordings if r.bias_offsets is not None}
    if biases is None:
        if len(stated_b) > 1:
            raise CalibrationError("the recordings were made at different biases: calibrate one bias setting at a time")
        biases = json.loads(stated_b.pop()) if stated_b else {}
    try:
        check_bias_offsets(biases)
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    return float(f_number), {k: int(v) for k, v in biases.items()}


def calibrate_sensor(recordings: list[CalibrationRecording], *, f_number: float | None = None,
                     biases: dict[str, int] | None = None, f_max_hz: float = F_MAX_ASSUMED_HZ) -> SensorCalibration:
    """Measure every recording and assemble the profile. CalibrationError for too few light levels,
    no edge, or a recording that cannot be used."""
    cards = [r for r in recordings if r.target == "card"]
    edges = [r for r in recordings if r.target == "edge"]
    darks = [r for r in recordings if r.target == "dark"]
    levels = sorted({r.lux * r.reflectance for r in cards})
    if len(levels) < MIN_CARD_LEVELS:
        raise CalibrationError(f"{len(levels)} light level(s) of the still card ({', '.join(f'{r.lux:g} lux' for r in cards) or 'none'}): "
                               f"record it at {MIN_CARD_LEVELS} or more, e.g. 1, 3, 10 and 30 lux")
    if not edges:
        raise CalibrationError("no edge recording: sweep a bright edge across the view (--edge FILE.raw@LUX) to measure K")
    f_number, offsets = _agreed(recordings, f_number, biases)
    out_cards, points = [], []
    for rec in cards:
        rate = measure_card(rec)
        if rate.pixels == 0:
            raise CalibrationError(f"{rec.name}: no events after the warm-up: record the card for a few seconds")
        out_cards.append((rec, rate))
        points.append(NoisePoint(rec.name, rec.lux, rec.reflectance, float(chip_lux(rec.lux * rec.reflectance, f_number)),
                                 rate.rate_hz, rate.on_hz, rate.off_hz, rate.pixels, rate.hot_pixels, rate.seconds))
    floors = [measure_card(rec) for rec in darks]
    dark_floor = float(np.mean([f.rate_hz for f in floors])) if floors else None
    out_edges, ks, edge_docs = [], [], []
    for rec in edges:
        fit = measure_edge(rec)
        e_chip = float(chip_lux(rec.lux * rec.reflectance, f_number))
        try:
            k = k_from_time_constant(fit.time_constant_s, e_chip, f_max_hz)
        except ValueError as exc:
            raise CalibrationError(f"{rec.name}: {exc}") from None
        out_edges.append((rec, fit, k))
        ks.append(k)
        edge_docs.append({"recording": rec.name, "lux": rec.lux, "reflectance": rec.reflectance,
                          "dark_reflectance": rec.dark_reflectance, "chip_lux": round(e_chip, 6),
                          "cutoff_hz": round(1.0 / (2 * math.pi * fit.time_constant_s), 2),
                          "k_hz_per_chip_lux": round(k, 3), **fit.to_dict()})
    log_k = np.log(ks)
    # the spread of several edges' K, or one tail's statistical error (an exponential's mean: 1 / sqrt(n))
    statistical = float(np.sqrt(np.mean([1.0 / f.tail_events for _, f, _ in out_edges]) / len(ks)))
    spread = float(np.std(log_k, ddof=1) / math.sqrt(len(ks))) if len(ks) > 1 else 0.0
    profile = SensorProfile(
        f_number=f_number, transmission=LENS_TRANSMISSION, k_hz_per_chip_lux=float(np.exp(log_k.mean())),
        k_relative_sd=max(statistical, spread), f_max_hz=float(f_max_hz), f_max_fitted=False,
        noise_points=tuple(sorted(points, key=lambda p: p.scene_irradiance)), dark_floor_hz=dark_floor,
        bias_offsets=offsets, edges=tuple(edge_docs),
    )
    return SensorCalibration(profile, out_cards, out_edges)
