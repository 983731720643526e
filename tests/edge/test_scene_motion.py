"""The scene's motion from all events: a moving pattern is followed, noise and chunking change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.events import make_events
from darkread.edge.scene_motion import SceneMotion, SceneMotionConfig

SENSOR = (1280, 720)


def moving_pattern(velocity_px_s: tuple[float, float], seconds: float = 0.6, seed: int = 0, noise_hz: float = 0.0):
    """Events of a rigid pattern of edges (random short strokes) moving at ``velocity_px_s``: every
    millisecond each stroke pixel fires with some probability where it is then; plus uniform noise."""
    rng = np.random.default_rng(seed)
    n_strokes = 600
    base = rng.uniform([100, 100], [1180, 620], (n_strokes, 2))
    along = np.arange(6)[:, None, None] * rng.choice([[1, 0], [0, 1]], n_strokes)[None, :, :]  # 6-px strokes
    points = (base[None, :, :] + along).reshape(-1, 2)
    xs, ys, ts = [], [], []
    for ms in range(int(seconds * 1000)):
        t = ms * 1000
        shift = np.asarray(velocity_px_s) * t / 1e6
        fire = rng.random(points.shape[0]) < 0.15
        p = np.round(points[fire] + shift).astype(int)
        keep = (p[:, 0] >= 0) & (p[:, 0] < SENSOR[0]) & (p[:, 1] >= 0) & (p[:, 1] < SENSOR[1])
        xs.append(p[keep, 0])
        ys.append(p[keep, 1])
        ts.append(np.full(int(keep.sum()), t) + rng.integers(0, 1000, int(keep.sum())))
        if noise_hz:
            k = rng.poisson(noise_hz * SENSOR[0] * SENSOR[1] / 1000)
            xs.append(rng.integers(0, SENSOR[0], k))
            ys.append(rng.integers(0, SENSOR[1], k))
            ts.append(t + rng.integers(0, 1000, k))
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    x, y = np.concatenate(xs)[order], np.concatenate(ys)[order]
    return make_events(x, y, rng.integers(0, 2, x.shape[0]), t[order])


@pytest.mark.parametrize("velocity", [(150.0, 0.0), (-80.0, 120.0), (0.0, -250.0)])
def test_a_moving_pattern_is_followed_to_within_a_sixth_of_its_motion(velocity) -> None:
    events = moving_pattern(velocity)
    scene = SceneMotion(SENSOR)
    scene.push(events)
    for t_us in (200_000, 400_000, 560_000):
        expected = np.asarray(velocity) * t_us / 1e6
        error = np.hypot(*(np.asarray(scene.at(t_us)) - expected))
        assert error <= 3.0 + 0.16 * np.hypot(*expected), (t_us, scene.at(t_us), expected)


def test_a_pattern_buried_in_dim_light_shot_noise_is_still_followed() -> None:
    """7 M noise events a second over the array against 0.5 M of the page's (as at 10 lux): phase
    correlation let the noise decide (no peak in a sixth of the slices, 20 px off after 0.4 s)."""
    velocity = np.array([0.0, -250.0])  # a walking head's bob
    scene = SceneMotion(SENSOR)
    scene.push(moving_pattern(tuple(velocity), noise_hz=8.0))
    for t_us in (200_000, 400_000, 560_000):
        found = scene.at(t_us)
        assert found is not None, t_us
        assert np.hypot(*(np.asarray(found) - velocity * t_us / 1e6)) <= 8.0, (t_us, found)


def test_a_still_scene_under_noise_does_not_drift() -> None:
    scene = SceneMotion(SENSOR)
    scene.push(moving_pattern((0.0, 0.0), noise_hz=2.0))
    assert np.hypot(*scene.at(590_000)) < 4.0


def test_the_chunking_of_the_stream_changes_nothing() -> None:
    events = moving_pattern((120.0, -60.0), seed=3)
    whole = SceneMotion(SENSOR)
    whole.push(events)
    pieces = SceneMotion(SENSOR)
    cuts = np.sort(np.random.default_rng(1).integers(0, events.shape[0], 40))
    for part in np.split(events, cuts):
        pieces.push(part)
    for t_us in range(0, 600_000, 37_000):
        assert pieces.at(t_us) == whole.at(t_us)


def test_before_any_event_there_is_no_offset_and_the_history_is_bounded() -> None:
    scene = SceneMotion(SENSOR, SceneMotionConfig(slice_us=1_000))
    assert scene.at(0) is None
    scene.push(moving_pattern((50.0, 0.0), seconds=1.2))  # 1,200 slices: more than are kept
    assert scene.at(1_190_000) is not None
    assert scene._times.shape[0] <= 1_000  # the bound is the point of this test


def test_noise_without_a_scene_gives_no_offset_rather_than_a_wandering_one() -> None:
    """Dim light: plenty of events, but slices that find no peak make the motion unknown (None)."""
    rng = np.random.default_rng(5)
    n = 400_000  # ~0.7 M noise events per second over the array, no page
    t = np.sort(rng.integers(0, 600_000, n))
    noise = make_events(rng.integers(0, SENSOR[0], n), rng.integers(0, SENSOR[1], n), rng.integers(0, 2, n), t)
    scene = SceneMotion(SENSOR)
    scene.push(noise)
    assert [scene.at(t_us) for t_us in (300_000, 450_000, 590_000)] == [None, None, None]
    lit = SceneMotion(SENSOR)  # the same noise over a page: the page's edges give a peak every slice
    lit.push(moving_pattern((60.0, 0.0), noise_hz=2.0))
    assert all(lit.at(t_us) is not None for t_us in (300_000, 450_000, 590_000))
