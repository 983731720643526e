"""A window's events moved back along the head's motion: the motion is found, the strokes sharpen,
still and bright windows are left alone."""

from __future__ import annotations

import numpy as np
import pytest
from factories import moving_strokes

from darkread.edge.deblur import DeblurConfig, deblur, deblur_window, estimate_smear, region_of, smear_of
from darkread.edge.fovea import FoveaConfig, in_window, window_events

SENSOR = (1280, 720)
ORIGIN = (540, 310)  # moving_strokes draws around this window
SHAPE = (100, 200)


def window_of(events):
    """The window's newest 1600 events, as the pipeline takes them."""
    return window_events(events, ORIGIN, FoveaConfig(height=SHAPE[0], width=SHAPE[1]), 1600)


def sharpness(events) -> float:
    """Sum of squared counts per pixel: events piled on fewer pixels score higher."""
    counts = np.bincount(events["y"].astype(np.int64) * SENSOR[0] + events["x"])
    return float((counts.astype(np.float64) ** 2).sum() / max(events.shape[0], 1))


@pytest.mark.parametrize("velocity", [(300.0, 0.0), (-150.0, 200.0), (0.0, -250.0)])
@pytest.mark.parametrize("noise_share", [0.0, 0.5])
def test_the_smear_of_a_moving_page_is_found_to_within_a_pixel(velocity, noise_share) -> None:
    events = moving_strokes(velocity, noise_share=noise_share)
    window = window_of(events)
    t_ref, span = int(window["t"][-1]), float(window["t"][-1] - window["t"][0])
    nearby = events[events["t"] >= window["t"][0]]
    found = estimate_smear(nearby, region_of(ORIGIN, SHAPE, SENSOR, 60), t_ref, span)
    expected = np.asarray(velocity) * span / 1e6
    assert np.hypot(*(np.asarray(found) - expected)) <= 1.0, (found, expected)


def test_deblurred_strokes_are_sharper() -> None:
    events = moving_strokes((300.0, 100.0))
    window = window_of(events)
    moved, smear = deblur_window(window, events, ORIGIN, SHAPE, SENSOR)
    assert np.hypot(*smear) > 5
    assert sharpness(moved) > 1.5 * sharpness(window)
    assert moved.dtype == window.dtype and moved.shape[0] > 0.8 * window.shape[0]


def test_a_still_page_is_left_where_it_is() -> None:
    events = moving_strokes((0.0, 0.0), noise_share=0.3)
    window = window_of(events)
    moved, smear = deblur_window(window, events, ORIGIN, SHAPE, SENSOR)
    assert np.hypot(*smear) <= 0.5
    assert sharpness(moved) >= 0.95 * sharpness(window)


def test_a_short_window_bright_light_is_returned_as_it_is() -> None:
    events = moving_strokes((300.0, 0.0), span_ms=2.0)
    window = window_of(events)
    moved, smear = deblur_window(window, events, ORIGIN, SHAPE, SENSOR)
    assert moved is window and smear == (0.0, 0.0)


def test_disabled_and_too_few_events_change_nothing() -> None:
    events = moving_strokes((300.0, 0.0))
    window = window_of(events)
    assert deblur_window(window, events, ORIGIN, SHAPE, SENSOR, DeblurConfig(enabled=False))[0] is window
    few = window[-50:]
    span = float(few["t"][-1] - few["t"][0])
    assert estimate_smear(few, region_of(ORIGIN, SHAPE, SENSOR, 60), int(few["t"][-1]), span) == (0.0, 0.0)


def test_deblur_keeps_the_window_and_leaves_the_input_alone() -> None:
    events = moving_strokes((300.0, 0.0))
    window = window_of(events)
    before = window.copy()
    t_ref, span = int(window["t"][-1]), float(window["t"][-1] - window["t"][0])
    moved = deblur(window, (20.0, -5.0), t_ref, span, ORIGIN, SHAPE)
    np.testing.assert_array_equal(window, before)
    assert moved.shape[0] < window.shape[0]  # events pushed past the window's edge are dropped
    assert moved["x"].min() >= ORIGIN[0] and moved["x"].max() < ORIGIN[0] + SHAPE[1]
    assert moved["y"].min() >= ORIGIN[1] and moved["y"].max() < ORIGIN[1] + SHAPE[0]
    newest = window[window["t"] == t_ref]
    assert np.isin(newest["x"], moved["x"]).all()  # the newest events do not move


def test_the_region_stays_on_the_sensor() -> None:
    assert region_of((0, 0), SHAPE, SENSOR, 60) == (0, 0, 260, 160)
    assert region_of((1080, 620), SHAPE, SENSOR, 60) == (1020, 560, 260, 160)


@pytest.mark.parametrize("bad", [{"slices": 1}, {"step_px": 0.0}, {"max_shift_px": 0}, {"margin_px": -1}, {"bin_px": 0}])
def test_bad_settings_are_refused(bad) -> None:
    with pytest.raises(ValueError, match="DeblurConfig"):
        DeblurConfig(**bad)


def test_no_smear_faster_than_a_head_is_taken() -> None:
    """On a short window a far peak is the text's own period (letters, lines repeat), not motion:
    the search stays within what a head can move in the span, and a peak at its edge is none."""
    events = moving_strokes((2000.0, 0.0), span_ms=6.0)
    window = window_of(events)
    t_ref, span = int(window["t"][-1]), float(window["t"][-1] - window["t"][0])
    nearby = events[events["t"] >= window["t"][0]]
    region = region_of(ORIGIN, SHAPE, SENSOR, 60)
    unbounded = estimate_smear(nearby, region, t_ref, span, DeblurConfig(max_speed_px_s=1e6))
    assert np.hypot(*unbounded) > 1000.0 * span / 1e6  # faster than any head: found without the bound
    assert estimate_smear(nearby, region, t_ref, span) == (0.0, 0.0)


def test_events_after_the_reference_time_do_not_break_the_search() -> None:
    """A real sensor's times jitter back: events past t_ref must not index a slice before the first."""
    events = moving_strokes((300.0, 0.0))
    window = window_of(events)
    span = float(window["t"][-1] - window["t"][0])
    t_ref = int(window["t"][-1] - span / 2)  # half the events lie after it
    found = estimate_smear(events[events["t"] >= window["t"][0]], region_of(ORIGIN, SHAPE, SENSOR, 60), t_ref, span)
    assert all(np.isfinite(found)) and max(map(abs, found)) <= DeblurConfig().max_shift_px


@pytest.mark.parametrize("velocity", [(300.0, 100.0), (0.0, 0.0)])
def test_the_smear_of_the_fields_is_the_smear_of_the_events(velocity) -> None:
    """``smear_of`` (coordinates and times of the region's events) is ``estimate_smear`` without the record copy."""
    events = moving_strokes(velocity, noise_share=0.3)
    window = window_of(events)
    t_ref, span = int(window["t"][-1]), float(window["t"][-1] - window["t"][0])
    nearby = events[events["t"] >= window["t"][0]]
    region = region_of(ORIGIN, SHAPE, SENSOR, 60)
    inside = nearby[in_window(nearby, *region)]
    found = smear_of(inside["x"], inside["y"], inside["t"], region, t_ref, span)
    assert found == estimate_smear(nearby, region, t_ref, span)
    assert smear_of(inside["x"][:10], inside["y"][:10], inside["t"][:10], region, t_ref, span) == (0.0, 0.0)  # too few
