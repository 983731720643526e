"""Head motion regimes: the standard draws unchanged, the grounded bands' amplitudes and spectra."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.models.synth.motion import (
    GAIT_PITCH_DEG,
    LINE_HZ,
    MOTION_LEVELS,
    MOTION_REGIMES,
    READING_SWEEP_DEG,
    STEP_HZ,
    TREMOR_DEG,
    TREMOR_HZ,
    random_motion,
)

RATE_HZ = 1000.0
SECONDS = 40.0


def head_deg(level: str, regime: str, seed: int) -> np.ndarray:
    """[N, 3] head angles (pitch, yaw, roll) in degrees, sampled at 1 kHz."""
    motion = random_motion(level, np.random.default_rng(seed), regime)
    t = np.arange(int(SECONDS * RATE_HZ)) / RATE_HZ
    return sum((o(t) for o in motion.head_deg), np.zeros((t.size, 3)))  # what Motion.at sums, at every sample


def band_rms(signal: np.ndarray, lo_hz: float, hi_hz: float) -> float:
    """RMS of the part of ``signal`` between ``lo_hz`` and ``hi_hz`` (its Hann-windowed spectrum: the
    slow reading motion's leakage stays out of the tremor's band)."""
    window = np.hanning(signal.size)
    spectrum = np.fft.rfft((signal - signal.mean()) * window)
    freq = np.fft.rfftfreq(signal.size, 1.0 / RATE_HZ)
    inside = (freq >= lo_hz) & (freq <= hi_hz)
    return float(np.sqrt(2.0 * np.sum(np.abs(spectrum[inside]) ** 2) / (signal.size * np.sum(window**2))))


def peak_hz(signal: np.ndarray, lo_hz: float, hi_hz: float) -> float:
    spectrum = np.abs(np.fft.rfft(signal - signal.mean()))
    freq = np.fft.rfftfreq(signal.size, 1.0 / RATE_HZ)
    inside = (freq >= lo_hz) & (freq <= hi_hz)
    return float(freq[inside][np.argmax(spectrum[inside])])


def test_standard_is_the_default_and_draws_as_before() -> None:
    """The default regime is the standard draws: the same random numbers give the same motion."""
    a = random_motion("walking", np.random.default_rng(5))
    b = random_motion("walking", np.random.default_rng(5), "standard")
    for oa, ob in zip(a.head_deg + a.trans_m + a.page_deg, b.head_deg + b.trans_m + b.page_deg, strict=True):
        np.testing.assert_array_equal(oa.amp, ob.amp)
        np.testing.assert_array_equal(oa.freq, ob.freq)
    assert MOTION_REGIMES[0] == "standard"


@pytest.mark.parametrize("regime, band_value", [("quiet", TREMOR_DEG.lo), ("central", TREMOR_DEG.central),
                                                ("strong", TREMOR_DEG.hi)])
def test_tremor_amplitude_and_spectrum_at_the_band_points(regime: str, band_value: float) -> None:
    """Pitch and yaw tremor: RMS of a sinusoid of the band's peak amplitude, all of it at 8-12 Hz."""
    angles = head_deg("still", regime, seed=11)
    for axis in (0, 1):
        rms = band_rms(angles[:, axis], TREMOR_HZ[0] - 0.5, TREMOR_HZ[1] + 0.5)
        assert rms == pytest.approx(band_value / np.sqrt(2), rel=0.05)
        assert band_rms(angles[:, axis], 2.0, TREMOR_HZ[0] - 0.5) < 0.05 * rms  # nothing between reading and tremor
        assert band_rms(angles[:, axis], TREMOR_HZ[1] + 0.5, 100.0) < 0.05 * rms


def test_reading_sweep_is_yaw_at_the_line_rate() -> None:
    angles = head_deg("still", "central", seed=3)
    yaw = angles[:, 1]
    f = peak_hz(yaw, 0.15, 2.0)
    assert LINE_HZ[0] - 0.05 <= f <= LINE_HZ[1] + 0.05
    amplitude = np.sqrt(2) * band_rms(yaw, f - 0.1, f + 0.1)
    assert amplitude == pytest.approx(READING_SWEEP_DEG.central, rel=0.1)


def test_grounded_draws_stay_inside_the_bands() -> None:
    for seed in range(20):
        angles = head_deg("still", "grounded", seed=seed)
        rms = band_rms(angles[:, 0], TREMOR_HZ[0] - 0.5, TREMOR_HZ[1] + 0.5)
        assert TREMOR_DEG.lo / np.sqrt(2) * 0.95 <= rms <= TREMOR_DEG.hi / np.sqrt(2) * 1.05


def test_band_ends_order_the_motion() -> None:
    """quiet < central < strong in every component the bands set (the gait's pitch included)."""
    tremor = [band_rms(head_deg("walking", r, seed=2)[:, 0], 7.5, 12.5) for r in ("quiet", "central", "strong")]
    assert tremor[0] < tremor[1] < tremor[2]
    gait = []
    for regime in ("quiet", "central", "strong"):
        pitch = head_deg("walking", regime, seed=2)[:, 0]
        f = peak_hz(pitch, STEP_HZ[0] - 0.1, STEP_HZ[1] + 0.1)
        gait.append(np.sqrt(2) * band_rms(pitch, f - 0.1, f + 0.1))
    assert gait == pytest.approx([GAIT_PITCH_DEG.lo, GAIT_PITCH_DEG.central, GAIT_PITCH_DEG.hi], rel=0.1)


@pytest.mark.parametrize("level", MOTION_LEVELS)
def test_every_level_draws_under_every_regime(level: str) -> None:
    for regime in MOTION_REGIMES:
        motion = random_motion(level, np.random.default_rng(0), regime)
        assert motion.level == level and motion.max_speed_deg_s() > 0


def test_unknown_regime_is_refused() -> None:
    with pytest.raises(ValueError, match="motion regime 'wild'"):
        random_motion("still", np.random.default_rng(0), "wild")
