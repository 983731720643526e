"""The grounded sensor drawn around a measured sensor profile: K in its narrow band, the noise process fitted to
the profile's curve; the suite and the session specs carry the profile."""

from __future__ import annotations

import math

import numpy as np
import pytest

from darkread.edge.calibrate.sensor_profile import NoisePoint, SensorProfile, save_sensor_profile
from darkread.edge.errors import CalibrationError
from darkread.edge.sources.evk4.photoreceptor import chip_lux
from darkread.lab.eval.suite import make_suite, select_entries
from darkread.models.synth.sensor import NOISE_FIT
from darkread.models.synth.sensor_profile import (
    K_MIN_SPREAD,
    fit_noise_constants,
    process_rate,
    profile_sensor_params,
)
from darkread.models.synth.session import SessionSpec, session_sensor

# a smooth stand-in for G (crossings per noise cycle vs threshold / sd): the fit is a pure function of it
TABLE = (np.linspace(0.5, 8.0, 60), 3.0 - 0.25 * np.linspace(0.5, 8.0, 60) ** 2)


def _profile(rates: list[float], k: float = 90.0, floor: float | None = None) -> SensorProfile:
    lux = [1.0, 3.0, 10.0, 30.0][: len(rates)]
    points = tuple(NoisePoint(f"card-{x:g}", x, 0.8, float(chip_lux(0.8 * x, 2.4)), r, r / 2, r / 2, 1024, 0, 3.0)
                   for x, r in zip(lux, rates, strict=True))
    return SensorProfile(f_number=2.4, k_hz_per_chip_lux=k, k_relative_sd=0.02, f_max_hz=5400.0, f_max_fitted=False,
                         noise_points=points, dark_floor_hz=floor)


def test_the_noise_fit_reproduces_a_curve_of_known_constants():
    truth = {"noise_electrons_per_s": 5e4, "noise_max_hz": 20.0, "noise_k_hz_per_chip_lux": 75.0, "dark_chip_lux": 0.004}
    chip = np.array([float(chip_lux(0.8 * x, 2.4)) for x in (1.0, 3.0, 10.0, 30.0)] + [0.0])
    curve = process_rate(chip, *(np.array([v]) for v in truth.values()), leak_hz=0.06 * 1.38, table=TABLE)
    fitted = fit_noise_constants(_profile(list(curve[:4]), floor=float(curve[4])), table=TABLE)
    again = process_rate(chip, *(np.array([v]) for v in fitted.values()), leak_hz=0.06 * 1.38, table=TABLE)
    assert np.all(np.abs(again / curve - 1) < 0.1), (again, curve)


def test_draws_around_the_profile(monkeypatch):
    import darkread.models.synth.sensor_profile as module

    monkeypatch.setattr(module, "crossing_table", lambda: TABLE)  # the table's own cost is the event sensor's
    profile = _profile([1.1, 1.0, 0.4, 0.1], k=90.0)
    rng = np.random.default_rng(0)
    draws = [profile_sensor_params(profile, rng, 5.0) for _ in range(50)]
    ks = np.array([d.k_hz_per_chip_lux for d in draws])
    assert np.all(np.abs(np.log(ks / 90.0)) <= K_MIN_SPREAD + 1e-9) and ks.std() > 0
    n = np.array([d.noise_electrons_per_s for d in draws])
    assert n.max() / n.min() <= 1.05**2 + 1e-6
    assert all(d.f_number == 2.4 and math.isfinite(d.f_max_hz) for d in draws)


def test_a_profile_at_other_biases_is_refused():
    profile = _profile([1.1, 1.0, 0.4])
    profile = SensorProfile(**{**profile.__dict__, "bias_offsets": {"diff_on": -30}})
    with pytest.raises(ValueError, match="non-factory biases"):
        profile_sensor_params(profile, np.random.default_rng(0), 5.0)


def test_sessions_and_the_suite_carry_the_profile(tmp_path, monkeypatch):
    import darkread.models.synth.sensor_profile as module

    monkeypatch.setattr(module, "crossing_table", lambda: TABLE)
    path = tmp_path / "profile.json"
    save_sensor_profile(path, _profile([1.1, 1.0, 0.4, 0.1], k=60.0))
    params = session_sensor(SessionSpec(regime="grounded", sensor_profile=str(path)), np.random.default_rng(1), 5.0)
    assert abs(math.log(params.k_hz_per_chip_lux / 60.0)) <= K_MIN_SPREAD + 1e-9
    assert params.noise_max_hz != NOISE_FIT["noise_max_hz"] or params.noise_electrons_per_s != NOISE_FIT["noise_electrons_per_s"]
    with pytest.raises(ValueError, match="grounded regime only"):
        session_sensor(SessionSpec(sensor_profile=str(path)), np.random.default_rng(1), 5.0)
    entries = select_entries(small=True, regime="grounded", sensor_profile=str(path))
    assert entries and all(e.recording_spec().sensor_profile == str(path) for e in entries)
    with pytest.raises(ValueError, match="--regime grounded"):
        make_suite(tmp_path / "suite", small=True, sensor_profile=str(path), progress=False)
    with pytest.raises(CalibrationError, match="sensor profile not found"):
        make_suite(tmp_path / "suite", small=True, regime="grounded", sensor_profile=str(tmp_path / "no.json"), progress=False)
