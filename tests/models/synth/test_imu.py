"""The synthetic gyroscope: the MEMS model's noise density and bias, and the head's rates it measures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from darkread.edge.imu_motion import rotation_matrices
from darkread.models.synth.imu import MemsGyro, quaternion_matrix, true_rates_device
from darkread.models.synth.motion import Motion, Oscillators


def test_noise_density_and_bias_statistics() -> None:
    gyro = MemsGyro(bias_walk_deg_s_rts=0.0, scale_sd=0.0)
    n = 20_000
    t = np.arange(n) / gyro.rate_hz
    rng = np.random.default_rng(0)
    reading = np.degrees(gyro.measure(t, np.zeros((n, 3)), rng))  # deg/s, device frame
    # white noise: per-sample sd = density * sqrt(rate); as a density (Welch-free: sd / sqrt(rate))
    chip = reading @ quaternion_matrix(*gyro.R_device_imu)  # back into the chip's axes, where it is per axis
    residual = chip - chip.mean(axis=0)
    density = residual.std(axis=0) / math.sqrt(gyro.rate_hz)
    assert density == pytest.approx(np.full(3, gyro.noise_density_deg_s_rthz), rel=0.08)  # (+ quantisation)
    # the turn-on bias: constant per recording, drawn with sd bias_sd over many recordings
    biases = np.array([np.degrees(gyro.measure(t[:2000], np.zeros((2000, 3)), np.random.default_rng(s))).mean(axis=0)
                       for s in range(200)])
    assert biases.std() == pytest.approx(gyro.bias_sd_deg_s, rel=0.15)


def test_the_bias_drifts_as_a_random_walk() -> None:
    gyro = MemsGyro(noise_density_deg_s_rthz=0.0, bias_sd_deg_s=0.0, scale_sd=0.0, lsb_deg_s=1e-9, bias_walk_deg_s_rts=0.01)
    t = np.arange(0, 100.0, 0.01)
    drift = np.array([np.degrees(gyro.measure(t, np.zeros((t.shape[0], 3)), np.random.default_rng(s)))[-1] for s in range(100)])
    assert drift.std() == pytest.approx(0.01 * math.sqrt(100.0), rel=0.2)


def test_rates_pass_through_the_chip_and_back() -> None:
    gyro = MemsGyro(noise_density_deg_s_rthz=0.0, bias_sd_deg_s=0.0, bias_walk_deg_s_rts=0.0, scale_sd=0.0, lsb_deg_s=1e-9)
    rates = np.random.default_rng(1).normal(0, 0.3, (50, 3))
    assert np.allclose(gyro.measure(np.arange(50) * 1e-3, rates, np.random.default_rng(2)), rates, atol=1e-9)


class _Scene:
    """The two things ``true_rates_device`` reads of a ``Scene``: the head's motion and the calibration."""

    def __init__(self, head: Oscillators, T_event_cpf: np.ndarray) -> None:
        self.motion = Motion("normal", (head,), (Oscillators.zero(),), (Oscillators.zero(),))
        self.calib = type("Calib", (), {"T_event_cpf": T_event_cpf})()


def test_the_heads_rate_in_the_device_frame() -> None:
    # the world turns about the camera's y axis by +a t (R_head): the camera turns by -a about its y,
    # which in CPF (x and y flipped) is +a about y
    rate_deg_s = 10.0
    head = Oscillators(amp=np.array([[0.0, rate_deg_s * 100.0, 0.0]]), freq=np.array([1.0 / (2 * math.pi * 100.0)]),
                       phase=np.zeros((1, 3)))  # sin(t / 100) * 100 * rate: a steady turn near t = 0
    scene = _Scene(head, np.diag([-1.0, -1.0, 1.0, 1.0]))
    w = true_rates_device(scene, np.array([0.0, 0.01]))  # type: ignore[arg-type]
    assert np.allclose(w, [[0.0, math.radians(rate_deg_s), 0.0]] * 2, atol=1e-6)
    assert np.allclose(rotation_matrices(np.zeros((1, 3))), np.eye(3))
