"""The dark profile switched on a real Evk4Camera: the bias registers the fake board receives."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from darkread.edge.bias_control import BiasController
from darkread.edge.config import SensorConfig
from darkread.edge.events import Events, empty_events
from darkread.edge.light import load_rate_curves
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4.bias_profiles import DARK, FACTORY, profile_offsets
from darkread.edge.sources.evk4.camera import Evk4Camera
from darkread.edge.sources.evk4.fake import FakeEvk4, FakeUsbBackend
from darkread.edge.telemetry import EdgeMetrics

CURVES = load_rate_curves()


def background(profile: str, lux: float, t0_s: float, seconds: float, rng: np.random.Generator) -> Events:
    """A still scene's background events over the whole sensor at the table's rate for ``lux``."""
    c = CURVES[profile]
    return uniform(float(np.exp(np.interp(np.log(lux), np.log(c.lux), np.log(c.rate_hz)))), t0_s, seconds, rng)


def uniform(rate: float, t0_s: float, seconds: float, rng: np.random.Generator) -> Events:
    n = rng.poisson(rate * regs.WIDTH * regs.HEIGHT * seconds)
    ev = empty_events(n)
    ev["x"], ev["y"], ev["p"] = rng.integers(0, regs.WIDTH, n), rng.integers(0, regs.HEIGHT, n), rng.integers(0, 2, n)
    ev["t"] = np.sort(int(t0_s * 1e6) + rng.integers(0, int(seconds * 1e6), n))
    return ev


def profile_writes(name: str) -> list[tuple[int, int]]:
    """The register writes that put every bias at factory value + the profile's offset."""
    return [(spec.addr, regs.bias_write_value(regs.FACTORY_BIAS_VALUES[bias] + profile_offsets(name)[bias]))
            for bias, spec in regs.BIASES.items()]


def test_dim_light_writes_the_dark_profile_and_bright_light_restores_factory(caplog: pytest.LogCaptureFixture) -> None:
    fake = FakeEvk4()
    camera = Evk4Camera(backend=FakeUsbBackend([fake]), sleep=lambda seconds: None)
    camera.open()
    metrics = EdgeMetrics()
    config = SensorConfig(min_dwell_s=2.0, estimate_s=1.0, settle_s=0.5, stride=2)
    controller = BiasController(config, camera, metrics, FACTORY)
    controller.begin()
    rng = np.random.default_rng(7)
    mark = len(fake.writes)
    with caplog.at_level(logging.INFO, logger="darkread.edge.bias_control"):
        for second in range(2):  # 6 lux: the first estimate (after 1 s) switches
            controller.push(background(FACTORY, 6.0, second * 1.0, 1.0, rng), None)
        dark_writes = fake.writes[mark:]
        assert dark_writes == profile_writes(DARK)
        assert camera.biases == profile_offsets(DARK) and controller.active == DARK
        assert metrics.totals["bias_switches"] == 1

        mark = len(fake.writes)
        t = 2.0
        while t < 6.0:  # 60 lux on the dark profile's own curve: back to factory once the dwell allows
            controller.push(background(DARK, 60.0, t, 0.5, rng), None)
            t += 0.5
        assert fake.writes[mark:] == profile_writes(FACTORY)
    assert camera.biases == profile_offsets(FACTORY) and controller.active == FACTORY
    assert metrics.totals["bias_switches"] == 2
    switched = [r.message for r in caplog.records if "biases switched" in r.message]
    assert len(switched) == 2 and "factory -> dark" in switched[0] and "dark -> factory" in switched[1]
    assert float(switched[0].split()[1]) == pytest.approx(6.0, rel=0.15)  # the line says the estimate
    snap = metrics.snapshot()
    assert snap.bias_profile == FACTORY and not snap.bias_advisory and snap.light_lux is not None and snap.light_lux > 25
    text = metrics.prometheus_text()
    assert "darkread_edge_bias_switches_total 2" in text
    assert 'darkread_edge_bias_profile{profile="factory",mode="applied"} 1' in text
    assert "darkread_edge_light_lux " in text
    camera.close()


def test_the_events_of_a_bias_write_settle_before_they_count() -> None:
    fake = FakeEvk4()
    camera = Evk4Camera(backend=FakeUsbBackend([fake]), sleep=lambda seconds: None)
    camera.open()
    controller = BiasController(SensorConfig(estimate_s=1.0, settle_s=0.5, stride=4), camera, EdgeMetrics(), FACTORY)
    controller.begin()
    rng = np.random.default_rng(1)
    controller.push(uniform(10.0, 0.0, 0.4, rng), None)  # the stream's start-up burst: not counted either
    controller.push(background(FACTORY, 6.0, 0.5, 1.01, rng), None)  # (counted from 0.5 s, the start settled)
    assert controller.active == DARK
    burst = uniform(10.0, 1.52, 0.4, rng)  # a burst of events right after the write (4x the noise) ...
    controller.push(burst, None)
    controller.push(background(DARK, 6.0, 2.0, 1.05, rng), None)
    assert controller.lux == pytest.approx(6.0, rel=0.15)  # ... is not counted
    camera.close()
