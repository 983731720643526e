"""The fits of `calibrate sensor` on synthetic arrays: background rate, the edge's time constant, the law inverted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from darkread.edge.calibrate.sensor_fit import (
    background_rate,
    edge_time_constant,
    noise_rate_at,
    truncated_exponential_tau,
)
from darkread.edge.sources.evk4.photoreceptor import k_from_time_constant, photoreceptor_cutoff_hz


def test_background_rate_counts_per_pixel_and_second_without_hot_pixels():
    rng = np.random.default_rng(0)
    w, h, seconds, rate = 40, 30, 5.0, 0.8
    n = rng.poisson(rate * w * h * seconds)
    x, y = rng.integers(100, 100 + w, n), rng.integers(50, 50 + h, n)
    t = rng.uniform(0, seconds * 1e6, n)
    p = rng.integers(0, 2, n)
    hot_t = rng.uniform(0, seconds * 1e6, 2000)  # one pixel at 400 Hz
    x, y = np.concatenate([x, [100] * 2000]), np.concatenate([y, [50] * 2000])
    t, p = np.concatenate([t, hot_t]), np.concatenate([p, np.ones(2000, int)])
    out = background_rate(x, y, p, t, 0.0, seconds * 1e6)
    assert out.hot_pixels == 1 and out.pixels == w * h - 1
    assert out.rate_hz == pytest.approx(rate, rel=0.05)
    assert out.on_hz + out.off_hz == pytest.approx(out.rate_hz)


def test_truncated_exponential_mean_with_background():
    rng = np.random.default_rng(1)
    tau, length = 2e-3, 6e-3
    lags = rng.exponential(tau, 20000)
    lags = lags[lags < length]
    background = rng.uniform(0, length, 1000)
    assert truncated_exponential_tau(np.concatenate([lags, background]), length, 1000.0) == pytest.approx(tau, rel=0.05)


def test_edge_time_constant_from_exponential_lags_behind_a_moving_edge():
    """Each pixel's ON events at exponential lags behind the edge's arrival, a sparse background of both polarities."""
    rng = np.random.default_rng(2)
    tau, speed = 1.5e-3, 8000.0  # s, px/s
    xs, ys = np.meshgrid(np.arange(600, 660), np.arange(300, 316))
    arrival = 10_000 + (xs.ravel() - 600) / speed * 1e6
    per_pixel = 10
    x = np.repeat(xs.ravel(), per_pixel)
    y = np.repeat(ys.ravel(), per_pixel)
    t = np.repeat(arrival, per_pixel) + rng.exponential(tau * 1e6, x.size)
    nb = 300
    x = np.concatenate([x, rng.integers(600, 660, nb)])
    y = np.concatenate([y, rng.integers(300, 316, nb)])
    t = np.concatenate([t, rng.uniform(0, 40_000, nb)])
    p = np.concatenate([np.ones(t.size - nb, int), rng.integers(0, 2, nb)])
    fit = edge_time_constant(x, y, p, t.astype(np.int64), 1280)
    assert fit.time_constant_s == pytest.approx(tau, rel=0.08)
    assert fit.speed_px_s == pytest.approx(speed, rel=0.1)


def test_no_edge_is_a_value_error():
    with pytest.raises(ValueError, match="saw the edge"):
        edge_time_constant(np.arange(10), np.zeros(10, int), np.ones(10, int), np.arange(10) * 1000, 1280)


def test_k_inverts_the_photoreceptor_law():
    k, f_max, e = 130.0, 5400.0, 0.6
    tau = 1.0 / (2 * math.pi * photoreceptor_cutoff_hz(e, k, f_max))
    assert k_from_time_constant(tau, e, f_max) == pytest.approx(k)
    with pytest.raises(ValueError, match="dimmer light"):
        k_from_time_constant(1.0 / (2 * math.pi * f_max * 1.1), e, f_max)


def test_noise_curve_reads_log_log_between_points_and_never_rises_beyond():
    levels, rates = np.array([1.0, 4.0, 16.0]), np.array([1.2, 0.6, 0.15])
    assert noise_rate_at(2.0, levels, rates)[0] == pytest.approx(math.sqrt(1.2 * 0.6))
    assert noise_rate_at(0.1, levels, rates)[0] == pytest.approx(1.2)
    assert noise_rate_at(64.0, levels, rates)[0] == pytest.approx(0.15 / 4)
