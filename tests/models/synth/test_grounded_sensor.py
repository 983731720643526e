"""The grounded sensor regime: its laws, its noise against the published curve, biases, a recording."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, replace

import numpy as np
import pytest

from darkread.edge.io.raw import read_raw
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4.bias_profiles import BIAS_PROFILES, outside_recommended, profile_offsets
from darkread.models.synth.biases import apply_biases, apply_profile
from darkread.models.synth.recording import RecordingSpec, write_recording
from darkread.models.synth.sensor import (
    NOISE_FIT,
    EventSensor,
    GroundedSensorParams,
    background_rate_curve,
    chip_lux,
    grounded_sensor_params,
    photoreceptor_cutoff_hz,
    random_sensor_params,
    regime_sensor_params,
)

FACTORY = dict(c_on=0.23, c_off=0.23, c_sigma=0.04, refractory_us=150.0, leak_rate_hz=0.06, leak_decades=0.35,
               hot_pixel_fraction=0.0)
# ON + OFF per pixel (Hz) at scene lux (reflectance 1, f/2.4), Noise2Image / Noise2Params on EVK4 at factory biases
PUBLISHED = {0.0: (0.15, 0.5), 1.0: (1.15, 1.28), 2.0: (1.25, 1.37), 5.0: (0.63, 0.99), 10.0: (0.23, 0.48), 30.0: (0.07, 0.14)}


def test_light_on_the_chip_follows_the_lens_law():
    assert chip_lux(100.0, 2.4) == pytest.approx(3.9, rel=0.01)  # 3.9 % of the scene at f/2.4
    assert chip_lux(100.0 * 0.8, 2.4) / chip_lux(100.0 * 0.05, 2.4) == pytest.approx(16.0)  # paper vs ink
    assert chip_lux(10.0, 1.2) == pytest.approx(4 * chip_lux(10.0, 2.4))  # one stop is twice the light


def test_photoreceptor_cutoff_is_linear_in_chip_light_below_its_ceiling():
    assert photoreceptor_cutoff_hz(0.01, 130.0, 5000.0) == pytest.approx(1.3, rel=1e-3)
    assert photoreceptor_cutoff_hz(1e6, 130.0, 5000.0) == pytest.approx(5000.0, rel=1e-3)
    # the worked example: at 5 scene lux and f/2.4, paper's time constant near 8 ms, ink's near 120 ms
    p = GroundedSensorParams(lux=5.0, dark_chip_lux=0.0)
    tau_ms = {r: 1e3 / (2 * math.pi * float(p.cutoff_of(np.float32(5.0 * r)))) for r in (0.8, 0.05)}
    assert tau_ms[0.8] == pytest.approx(8.0, rel=0.1) and tau_ms[0.05] == pytest.approx(122.0, rel=0.1)


def test_dark_current_is_a_floor_of_the_log_response_and_the_speed():
    p = GroundedSensorParams(lux=1.0, dark_chip_lux=0.01)
    dark, dim = p.log_intensity(np.float32(0.0)), p.log_intensity(np.float32(0.01))
    assert dark == pytest.approx(math.log(0.01), rel=1e-5) and dim - dark < 0.05  # 0.01 scene lux hides under the floor (a fifth of a threshold)
    assert float(p.cutoff_of(np.float32(0.0))) == pytest.approx(photoreceptor_cutoff_hz(0.01, p.k_hz_per_chip_lux, p.f_max_hz))


def test_the_standard_regime_is_untouched_and_grounded_draws_span_the_band():
    assert regime_sensor_params("standard", np.random.default_rng(3), 5.0) == random_sensor_params(np.random.default_rng(3), 5.0)
    assert "law" not in random_sensor_params(np.random.default_rng(3), 5.0).to_dict()
    ks = np.array([grounded_sensor_params(np.random.default_rng(s), 5.0).k_hz_per_chip_lux for s in range(400)])
    assert 40.0 <= ks.min() and ks.max() <= 400.0
    assert 100.0 < np.median(ks) < 160.0  # log-uniform over 40-400: its centre near the central 130
    doc = grounded_sensor_params(np.random.default_rng(1), 5.0, f_number=2.0).to_dict()
    assert doc["law"] == "grounded" and doc["f_number"] == 2.0 and "cutoff_hz" not in doc


def test_the_noise_signal_keeps_its_variance_for_any_step_length():
    p = GroundedSensorParams(lux=5.0, **{**FACTORY, "c_on": 50.0, "c_off": 50.0})  # thresholds out of reach: noise only
    image = np.full((40, 50), 5.0, dtype=np.float32)
    sd, _ = p.noise_sd_and_cutoff(image.reshape(-1))
    for dt_us in (125.0, 2000.0):
        sensor = EventSensor(p, image.shape, (0, 0), np.random.default_rng(0))
        sensor.reset(image, 0.0)
        for _ in range(200):
            sensor.step(image, dt_us)
        assert sensor.noise.std() == pytest.approx(float(sd[0]), rel=0.08)


def test_the_fitted_noise_process_reproduces_the_published_background_curve():
    params = GroundedSensorParams(lux=5.0, **FACTORY, **NOISE_FIT)
    lux = np.array(sorted(PUBLISHED))
    rates = background_rate_curve(params, lux, pixels=160, seconds=5.0)
    for x, rate in zip(lux, rates):
        lo, hi = PUBLISHED[float(x)]
        assert lo * 0.8 <= rate <= hi * 1.2, f"{x} lux: {rate:.3f} Hz outside {lo}-{hi} by more than 20 %"
    assert rates.argmax() in (1, 2)  # the peak at 1-2 lux, the dark floor below it


def test_a_threshold_change_predicts_its_own_noise_change():
    params = GroundedSensorParams(lux=5.0, **FACTORY, **NOISE_FIT)
    factory, dark = (background_rate_curve(p, np.array([5.0]), pixels=200, seconds=3.0)[0]
                     for p in (params, apply_profile(params, "dark")))
    assert dark > 1.5 * factory


def test_bias_offsets_map_onto_the_model_as_documented():
    p = grounded_sensor_params(np.random.default_rng(2), 5.0)
    same = apply_biases(p, {})
    assert {k: v for k, v in asdict(same).items() if k != "biases"} == {k: v for k, v in asdict(p).items() if k != "biases"}
    assert dict(same.biases) == {name: 0 for name in ("diff_on", "diff_off", "fo", "hpf", "refr")}
    dark = apply_profile(p, "dark")
    assert dark.c_on < p.c_on and dark.c_off < p.c_off and dark.f_max_hz < p.f_max_hz and dark.highpass_hz == 0.0
    assert apply_biases(p, {"diff_on": 110}).c_on == pytest.approx(p.c_on * math.e)
    assert apply_biases(p, {"refr": 60}).refractory_us == pytest.approx(p.refractory_us / math.e)
    assert apply_biases(p, {"hpf": 120}).highpass_hz > 1.0
    with pytest.raises(ValueError, match="unknown bias 'gain'"):
        apply_biases(p, {"gain": 3})
    with pytest.raises(ValueError, match="allowed range"):
        apply_biases(p, {"diff_on": 400})


def test_the_high_pass_lets_slow_changes_pass_silently():
    quiet = dict(FACTORY, c_sigma=0.0, leak_rate_hz=0.0, c_on=0.2, c_off=0.2)
    counts = []
    for hpf in (0, 120):
        p = apply_biases(GroundedSensorParams(lux=100.0, **quiet, noise_electrons_per_s=1e12), {"hpf": hpf})
        sensor = EventSensor(p, (1, 1), (0, 0), np.random.default_rng(0))
        sensor.reset(np.full((1, 1), 100.0, dtype=np.float32), 0.0, steady=False)
        n = 0
        for k in range(2000):  # a slow ramp: x e over 2 s
            n += sensor.step(np.full((1, 1), 100.0 * math.exp(k / 2000), dtype=np.float32), 1000.0).size
        counts.append(n)
    assert counts[0] >= 4 and counts[1] == 0


def test_bias_profiles_are_inside_openeb_recommended_ranges():
    for name in BIAS_PROFILES:
        offsets = profile_offsets(name)
        assert set(offsets) == set(regs.BIASES) and not outside_recommended(offsets)
    with pytest.raises(ValueError, match="bias profile 'night'"):
        profile_offsets("night")


def test_a_grounded_recording_states_its_lens_and_biases_and_decodes(tmp_path):
    spec = RecordingSpec(lux=10.0, motion="still", kind="pangram", seconds=0.3, seed=5, xheight_px=8.0, n_lines=2,
                         line_chars=20, regime="grounded", bias_profile="dark", f_number=2.0)
    meta = write_recording(tmp_path, spec, progress=False)
    on_disk = json.loads((tmp_path / "meta.json").read_text())
    assert on_disk["lens_f_number"] == 2.0 and on_disk["sensor_regime"] == "grounded"
    assert on_disk["biases"] == {"profile": "dark", "offsets": profile_offsets("dark")}
    assert on_disk["sensor"]["law"] == "grounded" and on_disk["sensor"]["biases"] == profile_offsets("dark")
    raw = read_raw(tmp_path / "events.raw")
    assert raw.events.size == meta["event_count"] > 100 and np.all(np.diff(raw.events["t"]) >= 0)
    x0, y0, w, h = meta["simulated_region_xywh"]
    inside = (raw.events["x"] >= x0) & (raw.events["x"] < x0 + w) & (raw.events["y"] >= y0) & (raw.events["y"] < y0 + h)
    density_in = inside.sum() / (w * h)
    density_out = (~inside).sum() / (1280 * 720 - w * h)
    assert density_in > 2 * density_out  # the page's edges fire above the background


def test_a_bias_profile_outside_the_grounded_regime_is_refused(tmp_path):
    spec = RecordingSpec(lux=10.0, seconds=0.2, regime="standard", bias_profile="dark")
    with pytest.raises(ValueError, match="grounded regime only"):
        write_recording(tmp_path, spec, progress=False)


def test_the_unsimulated_area_gets_the_grounded_background_rate():
    p = replace(GroundedSensorParams(lux=5.0, **FACTORY, **NOISE_FIT), hot_pixel_fraction=0.0)
    assert p.background_rate_hz() == pytest.approx(
        background_rate_curve(p, np.array([0.85 * 5.0]), pixels=512, seconds=4.0)[0])
