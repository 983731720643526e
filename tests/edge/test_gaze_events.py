"""Online gaze events: synthetic reading rows with known fixations, and the real reader of oz."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.gaze_events import (
    EVENT_DTYPE,
    EventKind,
    GazeEventClassifier,
    GazeEventConfig,
    angles_from_cpf,
    classify_gaze,
    fixations,
)


def reading_rows(rate_hz: float, noise_deg: float, seed: int = 0, blink_at_s: float | None = None):
    """Rows of a reader: 2 deg forward saccades, a 15 deg return sweep every 6 fixations; known onsets."""
    rng = np.random.default_rng(seed)
    onsets, centres, t = [], [], 0.0
    x, y = 0.0, 0.0
    for k in range(30):
        onsets.append(t)
        centres.append((x, y))
        t += rng.uniform(0.18, 0.32) + 0.03  # fixation + saccade
        if k % 6 == 5:
            x, y = 0.0, y + 1.0
        else:
            x += rng.uniform(1.5, 2.5)
    times = np.arange(0.0, t, 1.0 / rate_hz)
    idx = np.searchsorted(onsets, times, side="right") - 1
    xy = np.asarray(centres)[idx] + rng.normal(0.0, noise_deg, (times.size, 2))
    if blink_at_s is not None:
        xy[(times >= blink_at_s) & (times < blink_at_s + 0.15)] = np.nan
    return (times * 1e6).astype(np.int64), xy[:, 0], xy[:, 1], np.asarray(onsets)


@pytest.mark.parametrize("rate_hz", [30.0, 60.0, 90.0])
def test_fixation_onsets_of_a_synthetic_reader(rate_hz: float) -> None:
    t, x, y, onsets = reading_rows(rate_hz, noise_deg=0.3)
    ev = classify_gaze(t, x, y, GazeEventConfig().for_rate(rate_hz))
    found = fixations(ev)["t0_us"] / 1e6
    hits = sum(np.abs(found - o).min() <= 0.05 for o in onsets)
    assert hits >= 0.9 * len(onsets)
    assert len(found) <= 1.1 * len(onsets)
    assert (ev["kind"] == EventKind.SWEEP).sum() == 4  # five lines read


def test_events_come_once_in_time_order_and_chunking_does_not_matter() -> None:
    t, x, y, _ = reading_rows(60.0, noise_deg=0.3, seed=3)
    whole = classify_gaze(t, x, y)
    clf = GazeEventClassifier()
    parts = [clf.push(t[i:i + 7], x[i:i + 7], y[i:i + 7]) for i in range(0, t.size, 7)] + [clf.flush()]
    chunked = np.concatenate(parts)
    assert chunked.dtype == EVENT_DTYPE
    np.testing.assert_array_equal(whole, chunked)
    assert np.all(np.diff(whole["t0_us"]) >= 0)
    fx = fixations(whole)
    assert np.all(fx["t1_us"] >= fx["t0_us"]) and np.all(fx["n_rows"] >= 1)


def test_a_gap_of_invalid_rows_is_a_blink_between_two_fixations() -> None:
    t, x, y, _ = reading_rows(60.0, noise_deg=0.2, seed=1, blink_at_s=2.0)
    ev = classify_gaze(t, x, y)
    blinks = ev[ev["kind"] == EventKind.BLINK]
    assert len(blinks) == 1
    assert 1.98e6 <= blinks[0]["t0_us"] <= 2.0e6 and 2.15e6 <= blinks[0]["t1_us"] <= 2.17e6
    assert np.isnan(blinks[0]["x"])


def test_status_follows_the_eye_with_bounded_delay() -> None:
    cfg = GazeEventConfig()
    clf = GazeEventClassifier(cfg)
    assert clf.status().kind is None  # nothing seen yet
    period = int(cfg.period_us)
    rows = [(k * period, 0.0, 0.0) for k in range(20)]
    for row in rows:
        clf.push(*row)
    status = clf.status()
    assert status.kind == EventKind.FIXATION and status.accepted and status.since_us == 0
    t_jump = 20 * period
    for k in range(cfg.lookahead_rows + 4):  # a 5 deg saccade: the new fixation within the look-ahead
        clf.push(t_jump + k * period, 5.0, 0.0)
    status = clf.status()
    assert status.kind == EventKind.FIXATION and abs(status.x - 5.0) < 1e-9 and status.since_us == t_jump
    clf.push(t_jump + 40 * period, np.nan, np.nan)
    assert clf.status().kind == EventKind.BLINK


def test_noise_estimate_adapts_to_the_tracker() -> None:
    for sigma in (0.1, 0.6):
        t, x, y, _ = reading_rows(60.0, noise_deg=sigma, seed=2)
        clf = GazeEventClassifier()
        clf.push(t, x, y)
        assert clf.noise_deg == pytest.approx(sigma, rel=0.35)


def test_bad_input_and_conventions() -> None:
    with pytest.raises(ValueError, match="one value per row"):
        GazeEventClassifier().push([0, 1], [0.0], [0.0])
    with pytest.raises(ValueError, match="positive"):
        GazeEventConfig(rate_hz=0.0)
    x, y = angles_from_cpf(np.radians([10.0]), np.radians([-5.0]))  # CPF: x left, y up
    assert x[0] == pytest.approx(-10.0) and y[0] == pytest.approx(5.0)
    assert len(classify_gaze(np.zeros(0, np.int64), np.zeros(0), np.zeros(0))) == 0


@pytest.mark.shared
def test_fixation_onsets_of_the_oz_reader(shared_data) -> None:
    """EyeLink's 1000 Hz samples of a real reader at Aria's rates with Aria-like noise (~1.1 deg RMS)."""
    from darkread.lab.gaze import human
    from darkread.lab.gaze.scores import ARIA_RATES_HZ, oz_onset_scores

    raw = human.load_eyelink_asc(shared_data / "reading_gaze" / "oz" / "OZ_1trial.txt")
    print(f"\noz reader, {len(raw.fixations)} EyeLink fixations; noise {human.NoiseModel()}")
    print("| rate | fixation-onset F1 (50 ms) | precision | recall |")
    scores = {}
    for rate in ARIA_RATES_HZ:
        s = oz_onset_scores(raw, rate, seeds=range(3))
        scores[rate] = s
        print(f"| {rate:g} Hz | {s.f1:.3f} | {s.precision:.3f} | {s.recall:.3f} |")
    assert scores[60.0].f1 >= 0.88
    assert scores[30.0].f1 >= 0.78
    assert scores[90.0].f1 >= 0.88


def small_steps(rate_hz: float, step_deg: tuple[float, float], seed: int, noise_deg: float = 0.3):
    """24 fixations of 200-300 ms, each ``step_deg`` from the last (no saccade rows); known onsets."""
    rng = np.random.default_rng(seed)
    onsets, centres, t, pos = [], [], 0.0, np.zeros(2)
    for _ in range(24):
        onsets.append(t)
        centres.append(pos.copy())
        t += rng.uniform(0.2, 0.3)
        pos = pos + np.asarray(step_deg)
    times = np.arange(0.0, t, 1.0 / rate_hz)
    xy = np.asarray(centres)[np.searchsorted(onsets, times, side="right") - 1] + rng.normal(0.0, noise_deg, (times.size, 2))
    return (times * 1e6).astype(np.int64), xy[:, 0], xy[:, 1], np.asarray(onsets)


def test_small_steps_along_the_line_split_and_across_it_read_as_tracker_wander() -> None:
    """Reading saccades run along the line; a vertical difference counts half (``across_weight``)."""
    along = across = 0
    for seed in range(3):
        for step, kind in (((0.6, 0.0), "along"), ((0.0, 0.6), "across")):
            t, x, y, onsets = small_steps(60.0, step, seed)
            found = fixations(classify_gaze(t, x, y, GazeEventConfig()))["t0_us"] / 1e6
            hits = sum(np.abs(found - o).min() <= 0.05 for o in onsets)
            along += hits if kind == "along" else 0
            across += len(found) if kind == "across" else 0
    assert along >= 0.6 * 3 * 24
    assert across <= 0.2 * 3 * 24
    t, x, y, _ = small_steps(60.0, (0.0, 0.6), 0)
    isotropic = GazeEventConfig(across_weight=1.0)
    assert len(fixations(classify_gaze(t, x, y, isotropic))) >= 10  # the same steps, weighted fully
