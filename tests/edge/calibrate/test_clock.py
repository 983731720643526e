from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.calibrate.clock import (
    RgbFrames,
    fit_offset,
    gaze_speed,
    load_rgb_frames,
    predicted_fractions,
    refine_offset,
    shown_fractions,
    switches_from_triggers,
)
from darkread.edge.errors import CalibrationError
from darkread.edge.events import empty_triggers
from darkread.lab.fixtures.calibration_capture import shown_fraction, simulate_gaze_flow


def test_predicted_fractions_integrate_the_square_wave():
    switches = np.array([100.0, 300.0, 700.0])
    shown = np.array([True, False, True])
    mids = np.array([50.0, 100.0, 200.0, 300.0, 650.0, 900.0])
    exposure = np.full(mids.size, 100.0)
    expected = [0.0, 0.5, 1.0, 0.5, 0.0, 1.0]
    assert np.allclose(predicted_fractions(switches, shown, mids, exposure), expected)
    ref = shown_fraction(switches, shown, mids - 50, mids + 50)
    assert np.allclose(predicted_fractions(switches, shown, mids, exposure), ref)


def test_shown_fractions_from_levels_of_a_darkening_screen():
    levels = np.array([1.0, 1.0, 0.5, 0.2, 0.2, 0.8, 1.0, 1.0])
    f = shown_fractions(levels, window=4)
    assert np.allclose(f, [0.0, 0.0, 0.625, 1.0, 1.0, 0.25, 0.0, 0.0])
    assert np.isnan(shown_fractions(np.ones(6))).all()


def _frames(offset_us, rng, n_switch=10, exposure=16000.0):
    """Frames of a flashing screen rendered as flat grey images from the true square wave."""
    device_t0 = 8_000_000_000
    switch_device = device_t0 + np.cumsum(rng.uniform(90_000, 160_000, n_switch))
    shown = np.arange(n_switch) % 2 == 0
    mids = device_t0 + rng.uniform(0, 33_333) + np.arange(int((switch_device[-1] - device_t0) / 33_333) + 5) * 33_333
    f = shown_fraction(switch_device, shown, mids - exposure / 2, mids + exposure / 2)
    linear = 1.0 - 0.6 * f  # the board darkens the screen
    images = [np.full((8, 8), 255 * lv ** (1 / 2.2), dtype=np.float64).round().astype(np.uint8) for lv in linear]
    for im in images:
        im[:2] = 30  # a static, dark room around the screen
    frames = RgbFrames(mids.astype(np.int64), np.full(mids.size, exposure), images)
    return frames, switch_device + offset_us, shown


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_offset_recovers_the_offset_below_a_millisecond(seed):
    rng = np.random.default_rng(seed)
    true = -1_234_567_890.0
    frames, switch_event, shown = _frames(true, rng)
    onsets = switch_event + rng.normal(0, 50, switch_event.size)  # burst-onset jitter
    result = fit_offset(onsets, shown, frames)
    assert abs(result.offset_us - true) < 1000
    assert result.uncertainty_us < 2000
    assert result.n_mixed_frames >= 1


def test_fit_offset_needs_switches_and_a_visible_flash():
    rng = np.random.default_rng(4)
    frames, switch_event, shown = _frames(0.0, rng)
    with pytest.raises(CalibrationError, match="at least 2"):
        fit_offset(switch_event[:1], shown[:1], frames)
    flat = RgbFrames(frames.t_us, frames.exposure_us, [np.full((8, 8), 128, np.uint8)] * len(frames))
    with pytest.raises(CalibrationError, match="do not show"):
        fit_offset(switch_event, shown, flat)


def test_trigger_edges_give_switches():
    trig = empty_triggers(4)
    trig["t"] = [10, 20, 30, 40]
    trig["p"] = [1, 0, 1, 0]
    trig["id"] = [0, 0, 1, 1]
    t, shown = switches_from_triggers(trig, channel=0)
    assert list(t) == [10, 20] and list(shown) == [True, False]
    _, shown = switches_from_triggers(trig, rising_means_shown=False)
    assert list(shown) == [False, True, False, True]
    with pytest.raises(CalibrationError):
        switches_from_triggers(trig, channel=5)


def test_rgb_frame_list_is_read_in_time_order(tmp_path):
    import cv2

    for t in (200, 100):
        cv2.imwrite(str(tmp_path / f"{t}.png"), np.full((300, 400), t, np.uint8))
    (tmp_path / "rgb_frames.csv").write_text("timestamp_us,exposure_us,file\n200,8000,200.png\n100,8000,100.png\n")
    frames = load_rgb_frames(tmp_path / "rgb_frames.csv")
    assert list(frames.t_us) == [100, 200]
    assert max(frames.images[0].shape) == 128 and frames.images[1].mean() == 200
    (tmp_path / "bad.csv").write_text("timestamp_us,exposure_us,file\nx,8000,100.png\n")
    with pytest.raises(CalibrationError, match="bad.csv:2"):
        load_rgb_frames(tmp_path / "bad.csv")


def test_gaze_speed_masks_saccades():
    t = np.arange(40) * 16_667
    uv = np.c_[np.arange(40) * 0.5, np.zeros(40)]
    uv[20:] += 60.0  # a saccade between samples 19 and 20
    mid, v, fixation = gaze_speed(t, uv, saccade_px_per_s=600.0, span=2)
    assert np.allclose(v[fixation], 0.5 / 0.016667, rtol=1e-3)
    assert not fixation[(mid > t[17]) & (mid < t[22])].any()


@pytest.mark.parametrize("seed", [0, 1])
def test_refinement_recovers_a_wrong_offset_within_two_ms(seed):
    scene = simulate_gaze_flow(seed)
    result = refine_offset(scene.events["t"], scene.gaze_t_device_us, scene.gaze_pixels, scene.offset_us + 15_000)
    assert abs(result.offset_us - scene.offset_us) < 2000
    assert result.peak_correlation > 0.5
    assert abs(result.correction_us + 15_000) < 2000


def test_activity_counted_in_chunks_equals_counted_at_once():
    from darkread.edge.calibrate.clock import ActivityCounter

    t = np.sort(np.random.default_rng(5).integers(1_000_000, 1_100_000, 5000))
    whole, parts = ActivityCounter(2000), ActivityCounter(2000)
    whole.add(t)
    for chunk in np.array_split(t, 7):
        parts.add(chunk)
    assert parts.start_us == whole.start_us
    assert np.array_equal(parts.counts, whole.counts) and parts.counts.sum() == t.size


def test_lazy_frames_are_read_at_full_size_when_used(tmp_path):
    import cv2

    cv2.imwrite(str(tmp_path / "1.png"), np.full((300, 400), 77, np.uint8))
    (tmp_path / "rgb_frames.csv").write_text("timestamp_us,exposure_us,file\n1,8000,1.png\n")
    frames = load_rgb_frames(tmp_path / "rgb_frames.csv", lazy=True)
    assert frames.images[0].shape == (300, 400) and frames.images[0].mean() == 77
    (tmp_path / "missing.csv").write_text("timestamp_us,exposure_us,file\n1,8000,nope.png\n")
    with pytest.raises(CalibrationError, match="nope.png"):
        load_rgb_frames(tmp_path / "missing.csv", lazy=True)
