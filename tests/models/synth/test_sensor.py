from __future__ import annotations

import math

import numpy as np

from darkread.models.synth.sensor import EventSensor, SensorParams, background_events


def _quiet(**kw) -> SensorParams:
    """No noise, no photoreceptor lag (cut-off far above the step rate), no dark floor."""
    base = dict(
        lux=100.0, c_on=0.2, c_off=0.2, c_sigma=0.0, refractory_us=0.0, cutoff_hz=1e9, cutoff_half_lux=1e-9,
        dark_lux=1e-9, shot_rate_100lux_hz=0.0, leak_rate_hz=0.0, leak_decades=0.0, hot_pixel_fraction=0.0,
    )
    base.update(kw)
    return SensorParams(**base)


def _sensor(params: SensorParams, i0: float, shape=(1, 1)) -> EventSensor:
    s = EventSensor(params, shape, (10, 20), np.random.default_rng(0))
    s.reset(np.full(shape, i0, dtype=np.float32), 1000.0, steady=False)
    return s


def test_brightness_step_gives_right_count_polarity_and_interpolated_times():
    s = _sensor(_quiet(), 10.0)
    ratio = math.exp(3.5 * 0.2)  # 3.5 thresholds up -> 3 ON events
    ev = s.step(np.full((1, 1), 10.0 * ratio, dtype=np.float32), 1000.0)
    assert ev.size == 3
    assert np.all(ev["p"] == 1)
    assert np.all(ev["x"] == 10) and np.all(ev["y"] == 20)
    expected = 1000.0 + np.array([1, 2, 3]) / 3.5 * 1000.0  # linear interpolation of the crossings
    np.testing.assert_allclose(ev["t"], np.floor(expected), atol=1)
    # the residual half threshold stays: going back down by 1 threshold fires exactly one OFF
    ev2 = s.step(np.full((1, 1), 10.0 * ratio * math.exp(-0.2 * 1.49), dtype=np.float32), 1000.0)
    assert ev2.size == 0
    ev3 = s.step(np.full((1, 1), 10.0 * ratio * math.exp(-0.2 * 1.6), dtype=np.float32), 1000.0)
    assert ev3.size == 1 and ev3["p"][0] == 0


def test_refractory_drops_events_but_reference_advances():
    s = _sensor(_quiet(refractory_us=300.0), 10.0)
    ev = s.step(np.full((1, 1), 10.0 * math.exp(10.5 * 0.2), dtype=np.float32), 1000.0)  # 10 crossings, ~95 us apart
    assert 1 < ev.size < 10
    assert np.all(np.diff(ev["t"]) >= 299)
    np.testing.assert_allclose(s.ref[0], math.log(10.0) + 10 * 0.2, atol=1e-5)
    # nothing left to cross: a further step at the same brightness is silent
    assert s.step(np.full((1, 1), 10.0 * math.exp(10.5 * 0.2), dtype=np.float32), 1000.0).size == 0


def test_refractory_spans_steps():
    s = _sensor(_quiet(refractory_us=5000.0), 10.0)
    first = s.step(np.full((1, 1), 10.0 * math.exp(1.5 * 0.2), dtype=np.float32), 1000.0)
    second = s.step(np.full((1, 1), 10.0 * math.exp(2.5 * 0.2), dtype=np.float32), 1000.0)
    assert first.size == 1 and second.size == 0


def test_thresholds_are_per_pixel_and_fixed():
    params = _quiet(c_sigma=0.04)
    s = _sensor(params, 10.0, shape=(50, 50))
    c_on = s.c_on.copy()
    assert 0.03 < c_on.std() < 0.05
    rng = np.random.default_rng(1)
    for _ in range(5):
        s.step(rng.uniform(5, 20, (50, 50)).astype(np.float32), 500.0)
    np.testing.assert_array_equal(s.c_on, c_on)


def test_noise_rises_as_light_falls():
    counts = []
    for lux in (1000.0, 5.0):
        p = SensorParams(lux=lux, shot_rate_100lux_hz=0.2, leak_rate_hz=0.0, hot_pixel_fraction=0.0)
        s = EventSensor(p, (40, 40), (0, 0), np.random.default_rng(2))
        img = np.full((40, 40), 0.85 * lux, dtype=np.float32)
        s.reset(img, 0.0)
        counts.append(sum(s.step(img, 500.0).size for _ in range(200)))
    assert counts[1] > 20 * max(counts[0], 1)


def test_background_events_stay_outside_the_simulated_region():
    p = SensorParams(lux=30.0)
    ev = background_events(p, 1_000, 101_000, (1280, 720), (100, 100, 200, 100), np.random.default_rng(3))
    assert ev.size > 1000
    inside = (ev["x"] >= 100) & (ev["x"] < 300) & (ev["y"] >= 100) & (ev["y"] < 200)
    assert not inside.any()
    assert np.all(np.diff(ev["t"]) >= 0) and ev["t"].min() >= 1_000 and ev["t"].max() < 101_000


def test_the_fast_photoreceptor_regime_is_the_standard_draw_with_a_faster_photoreceptor_in_the_dark():
    from dataclasses import asdict

    from darkread.models.synth.sensor import random_sensor_params, regime_sensor_params

    standard = random_sensor_params(np.random.default_rng(7), 5.0)
    fast_rng = np.random.default_rng(7)
    fast = regime_sensor_params("fast-photoreceptor", fast_rng, 5.0)
    used = np.random.default_rng(7)
    random_sensor_params(used, 5.0)
    assert fast_rng.random() == used.random()  # the same random numbers used: the rest of the scene stays put
    same = {k: v for k, v in asdict(fast).items() if k not in ("cutoff_hz", "cutoff_half_lux")}
    assert same == {k: v for k, v in asdict(standard).items() if k not in ("cutoff_hz", "cutoff_half_lux")}
    assert math.isclose(fast.cutoff_hz, 2.5 * standard.cutoff_hz) and math.isclose(fast.cutoff_half_lux, standard.cutoff_half_lux / 5)

    def time_constant_ms(p, irradiance=0.85 * 5.0):  # a paper pixel at 5 lux
        return 1e3 / (2 * math.pi * p.cutoff_hz * irradiance / (irradiance + p.cutoff_half_lux))

    assert time_constant_ms(fast) < time_constant_ms(standard) / 5
    # over the draws: the standard photoreceptor answers in 4-50 ms at 5 lux, the fast one in 0.4-4.2 ms
    taus = [(time_constant_ms(random_sensor_params(np.random.default_rng(s), 5.0)),
             time_constant_ms(regime_sensor_params("fast-photoreceptor", np.random.default_rng(s), 5.0))) for s in range(200)]
    assert 3.5 < min(t for t, _ in taus) and max(t for t, _ in taus) < 51
    assert 0.35 < min(f for _, f in taus) and max(f for _, f in taus) < 4.3
