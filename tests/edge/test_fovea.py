"""Foveation: window placement and clamping, the window test, crops, moving-gaze crops."""

from __future__ import annotations

import numpy as np
import pytest
from factories import random_events
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.events import make_events
from darkread.edge.fovea import (
    FoveaConfig,
    crop,
    crop_along_track,
    in_window,
    origins_along_gaze,
    window_origin,
    window_origins,
)

SENSOR = (1280, 720)


def naive_crop(events, x0, y0, cfg=FoveaConfig()):
    x, y = events["x"].astype(int), events["y"].astype(int)
    return events[(x >= x0) & (x < x0 + cfg.width) & (y >= y0) & (y < y0 + cfg.height)]


def test_window_is_centred_on_the_gaze_pixel() -> None:
    assert window_origin((640.0, 360.0), SENSOR) == (540, 310)
    assert window_origin((640.4, 359.6), SENSOR) == (540, 310)  # nearest pixel
    assert window_origin((640.6, 360.0), SENSOR) == (541, 310)


@pytest.mark.parametrize(
    ("center", "origin"),
    [((0.0, 0.0), (0, 0)), ((-50.0, 900.0), (0, 620)), ((1279.0, 719.0), (1080, 620)), ((99.0, 49.0), (0, 0))],
)
def test_window_is_clamped_inside_the_sensor(center, origin) -> None:
    assert window_origin(center, SENSOR) == origin


def test_window_origin_rejects_nan_and_vector_version_keeps_it() -> None:
    with pytest.raises(ValueError):
        window_origin((np.nan, 3.0), SENSOR)
    origins = window_origins(np.array([[640.0, 360.0], [np.nan, np.nan]]), SENSOR)
    assert origins[0].tolist() == [540, 310] and np.isnan(origins[1]).all()


def test_small_sensor_gives_origin_zero() -> None:
    assert window_origin((100.0, 30.0), (150, 60)) == (0, 0)


@pytest.mark.parametrize(("x0", "y0"), [(0, 0), (540, 310), (1080, 620), (3, 700)])
def test_crop_equals_naive_mask_and_keeps_sensor_coordinates(x0: int, y0: int) -> None:
    events = random_events(20_000, seed=x0 + y0)
    out = crop(events, x0, y0)
    assert np.array_equal(out, naive_crop(events, x0, y0))
    assert out.shape[0] > 0 or (x0, y0) == (3, 700)
    if out.shape[0]:
        assert out["x"].min() >= x0 and out["x"].max() < x0 + 200
        assert out["y"].min() >= y0 and out["y"].max() < y0 + 100
    assert np.all(np.diff(out["t"]) >= 0)


def test_crop_of_empty_and_edges() -> None:
    assert crop(random_events(0), 10, 10).shape == (0,)
    edges = make_events([10, 209, 210, 9, 10], [20, 119, 20, 20, 120], 1, [1, 2, 3, 4, 5])
    assert crop(edges, 10, 20)["t"].tolist() == [1, 2]
    with pytest.raises(ValueError):
        crop(edges, -1, 0)


def test_crop_along_track_uses_each_events_own_window() -> None:
    events = make_events([50, 50, 700, 700, 5], [50, 50, 350, 350, 5], 1, [0, 1, 2, 3, 4])
    origins = np.array([[0, 0], [600, 300], [600, 300], [0, 0], [np.nan, np.nan]])
    assert crop_along_track(events, origins)["t"].tolist() == [0, 2]
    with pytest.raises(ValueError):
        crop_along_track(events, origins[:2])


def test_crop_along_track_with_a_fixed_origin_equals_crop() -> None:
    events = random_events(5_000, seed=3)
    origins = np.tile([540.0, 310.0], (events.shape[0], 1))
    assert np.array_equal(crop_along_track(events, origins), crop(events, 540, 310))


def test_in_window_is_the_naive_four_comparisons() -> None:
    events = random_events(10_000, seed=1)
    inside = in_window(events, 540, 310, 200, 100)
    assert np.array_equal(events[inside], naive_crop(events, 540, 310))
    # a 100x200 window is 2.2 % of the sensor; uniform events follow that share
    assert inside.mean() == pytest.approx(200 * 100 / (1280 * 720), abs=0.005)
    assert not in_window(make_events([539, 740, 600], [320, 320, 410], 1, [0, 1, 2]), 540, 310, 200, 100).any()


def test_origins_along_gaze_look_up_the_gaze_once_per_millisecond() -> None:
    asked: list[np.ndarray] = []

    def gaze(t_us: np.ndarray) -> np.ndarray:
        asked.append(np.asarray(t_us))
        return np.tile([640.0, 360.0], (len(t_us), 1))

    t = np.array([10, 20, 999, 1000, 2500, 2501])
    origins = origins_along_gaze(t, gaze, SENSOR)
    assert origins.tolist() == [[540, 310]] * 6
    assert asked[0].tolist() == [500, 1500, 2500]  # the middle of each millisecond holding events
    assert origins_along_gaze(np.array([], np.int64), gaze, SENSOR).shape == (0, 2)


@settings(max_examples=300, deadline=None)
@given(
    u=st.floats(-200.0, 1500.0, allow_nan=False), v=st.floats(-200.0, 900.0, allow_nan=False),
    width=st.integers(1, 1400), height=st.integers(1, 800),
)
def test_window_origin_is_window_origins_of_one_centre(u: float, v: float, width: int, height: int) -> None:
    """The scalar version (plain floats, per frame) and the vectorised one place a window alike."""
    expected = window_origins(np.array([[u, v]]), (width, height))[0]
    assert window_origin((u, v), (width, height)) == (int(expected[0]), int(expected[1]))
