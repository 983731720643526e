"""The light level from the background events, and the hysteresis that picks the bias profile."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from darkread.edge.bias_control import BiasController, profile_named
from darkread.edge.config import SensorConfig, load_config
from darkread.edge.events import Events, empty_events
from darkread.edge.light import (
    MIN_TILES,
    ProfileRule,
    ProfileState,
    RateCurve,
    TileGrid,
    background_rate_hz,
    load_rate_curves,
    next_profile,
    profile_sequence,
    usable_tiles,
)
from darkread.edge.sources.evk4.bias_profiles import DARK, FACTORY, profile_offsets
from darkread.edge.telemetry import EdgeMetrics

CURVES = load_rate_curves()
RULE = ProfileRule()


def still_scene(rate_hz: float, seconds: float, wh: tuple[int, int], rng: np.random.Generator, t0_us: int = 0,
                edge_rect: tuple[int, int, int, int] | None = None, edge_rate_hz: float = 0.0) -> Events:
    """Background events at ``rate_hz`` per pixel everywhere (Poisson), plus a moving pattern's many
    events inside ``edge_rect`` (the page being read), time-sorted."""
    width, height = wh
    n = rng.poisson(rate_hz * width * height * seconds)
    x, y = rng.integers(0, width, n), rng.integers(0, height, n)
    if edge_rect is not None:
        ex, ey, ew, eh = edge_rect
        m = rng.poisson(edge_rate_hz * ew * eh * seconds)
        x = np.concatenate([x, rng.integers(ex, ex + ew, m)])
        y = np.concatenate([y, rng.integers(ey, ey + eh, m)])
    ev = empty_events(x.size)
    ev["x"], ev["y"] = x, y
    ev["p"] = rng.integers(0, 2, x.size)
    ev["t"] = np.sort(t0_us + rng.integers(0, int(seconds * 1e6), x.size))
    return ev


def estimate(events: Events, wh: tuple[int, int], seconds: float, curve: RateCurve,
             gaze_window: tuple[int, int, int, int] | None = None) -> float:
    grid = TileGrid(*wh)
    excluded = grid.touching(gaze_window) if gaze_window is not None else None
    rate = background_rate_hz(grid.counts(events), grid.areas(), usable_tiles(grid, excluded), seconds)
    assert rate is not None
    return float(curve.lux_of(rate))


def curve_rate(profile: str, lux: float) -> float:
    c = CURVES[profile]
    return float(np.exp(np.interp(np.log(lux), np.log(c.lux), np.log(c.rate_hz))))


# -- the shipped table -------------------------------------------------------------------------------

def test_the_shipped_table_has_both_profiles_and_the_dark_one_is_noisier() -> None:
    assert set(CURVES) == {FACTORY, DARK}
    for lux in (5.0, 10.0, 20.0):
        assert curve_rate(DARK, lux) > 1.5 * curve_rate(FACTORY, lux)


def test_total_darkness_reads_as_dark_on_either_profile() -> None:
    """The curve is not monotonic: no light at all gives the dark-current floor's rate, which read on the
    falling side must still lie below the threshold that keeps (or puts) the sensor in the dark profile."""
    assert float(CURVES[FACTORY].lux_of(CURVES[FACTORY].dark_hz)) < RULE.dark_below_lux
    assert float(CURVES[DARK].lux_of(CURVES[DARK].dark_hz)) < RULE.bright_above_lux


def test_rates_above_the_peak_read_as_the_peaks_lux_and_tiny_rates_as_bright() -> None:
    curve = CURVES[FACTORY]
    peak_lux = float(curve.lux[np.argmax(curve.rate_hz)])
    assert float(curve.lux_of(10 * curve.rate_hz.max())) == pytest.approx(peak_lux)
    assert float(curve.lux_of(0.0)) == pytest.approx(float(curve.lux[-1]))


# -- the estimator -----------------------------------------------------------------------------------

@pytest.mark.parametrize("profile", [FACTORY, DARK])
@pytest.mark.parametrize("lux", [3.0, 6.0, 12.0, 20.0, 30.0])
def test_estimate_lands_at_the_light_of_a_still_scene(profile: str, lux: float) -> None:
    rng = np.random.default_rng(int(lux * 10))
    wh = (1280, 720)
    events = still_scene(curve_rate(profile, lux), 1.0, wh, rng)
    assert estimate(events, wh, 1.0, CURVES[profile]) == pytest.approx(lux, rel=0.15)


def test_a_moving_page_and_the_gaze_window_do_not_bias_the_estimate() -> None:
    """A third of the sensor fires 20x the background (a page moving under the head): the low quantile
    of the tiles and the gaze window's exclusion keep the estimate where the still scene puts it."""
    rng = np.random.default_rng(1)
    wh = (1280, 720)
    page = (0, 0, 1280, 240)
    window = (500, 300, 200, 100)
    events = still_scene(curve_rate(FACTORY, 10.0), 1.0, wh, rng, edge_rect=page, edge_rate_hz=5.0)
    read = still_scene(0.0, 1.0, wh, rng, edge_rect=window, edge_rate_hz=50.0)  # the text under the gaze
    events = np.sort(np.concatenate([events, read]), order="t")
    assert estimate(events, wh, 1.0, CURVES[FACTORY], gaze_window=window) == pytest.approx(10.0, rel=0.15)
    assert estimate(events, wh, 1.0, CURVES[FACTORY]) == pytest.approx(10.0, rel=0.15)  # the quantile alone copes too


def test_too_few_usable_tiles_give_no_estimate() -> None:
    grid = TileGrid(1280, 720)
    touched = np.ones(grid.shape, dtype=bool)
    touched[:3, :3] = False  # the gaze window's tiles all but 9
    usable = usable_tiles(grid, touched)
    assert int(usable.sum()) == 9 < MIN_TILES
    assert background_rate_hz(np.zeros(grid.shape), grid.areas(), usable, 1.0) is None


def test_tiles_at_the_sensor_edge_count_their_own_area() -> None:
    grid = TileGrid(100, 50, tile_px=40)
    assert grid.shape == (2, 3)
    np.testing.assert_array_equal(grid.areas(), [[1600, 1600, 800], [400, 400, 200]])


# -- the hysteresis ----------------------------------------------------------------------------------

def test_enter_below_leave_above_and_stay_between() -> None:
    t = np.arange(8) * 20.0  # an estimate every 20 s (longer than the dwell)
    lux = np.array([40, 20, 14, 20, 24, 26, 20, 10], dtype=float)
    assert profile_sequence(lux, t, RULE) == [FACTORY, FACTORY, DARK, DARK, DARK, FACTORY, FACTORY, DARK]


def test_noisy_estimates_around_a_threshold_do_not_flap() -> None:
    """Estimates once a second scattered by 10 % (several times the estimator's own spread) around the
    entry threshold: one switch into dark and none back; a rule without the gap and the dwell flaps."""
    rng = np.random.default_rng(0)
    lux = RULE.dark_below_lux * np.exp(rng.normal(0.0, 0.1, 300))
    t = np.arange(300.0)
    profiles = profile_sequence(lux, t, RULE)
    assert sum(a != b for a, b in zip(profiles, profiles[1:])) == 1 and profiles[-1] == DARK
    bare = profile_sequence(lux, t, ProfileRule(RULE.dark_below_lux, RULE.dark_below_lux + 1e-9, 0.0))
    assert sum(a != b for a, b in zip(bare, bare[1:])) > 50


def test_the_dwell_time_holds_a_switch_back() -> None:
    state = next_profile(ProfileState(FACTORY), 5.0, 100.0, RULE)
    assert state == ProfileState(DARK, 100.0)
    assert next_profile(state, 100.0, 100.0 + RULE.min_dwell_s - 0.5, RULE) == state
    assert next_profile(state, 100.0, 100.0 + RULE.min_dwell_s, RULE).profile == FACTORY


# -- the controller on a source without biases (a replay) ---------------------------------------------

class ReplayLike:
    """What the controller sees of a replayed recording: a size and no way to change its biases."""

    width, height = 320, 240


def test_a_replay_is_advised_not_switched(caplog: pytest.LogCaptureFixture) -> None:
    metrics = EdgeMetrics()
    controller = BiasController(SensorConfig(stride=1), ReplayLike(), metrics, FACTORY)
    controller.begin()
    rng = np.random.default_rng(3)
    with caplog.at_level(logging.INFO, logger="darkread.edge.bias_control"):
        for second in range(3):
            controller.push(still_scene(curve_rate(FACTORY, 6.0), 1.0, (320, 240), rng, t0_us=second * 1_000_000), None)
    assert controller.advisory and controller.active == FACTORY and controller.state.profile == DARK
    assert controller.lux == pytest.approx(6.0, rel=0.2)
    assert metrics.totals["bias_switches"] == 1
    assert sum("would switch the biases factory -> dark" in r.message for r in caplog.records) == 1
    snap = metrics.snapshot()
    assert snap.bias_profile == DARK and snap.bias_advisory and "biases dark (advisory)" in snap.log_line()
    assert 'darkread_edge_bias_profile{profile="dark",mode="advisory"} 1' in metrics.prometheus_text()


def test_a_recording_without_stated_biases_gives_no_estimate() -> None:
    metrics = EdgeMetrics()
    controller = BiasController(SensorConfig(), ReplayLike(), metrics, None)
    controller.begin()
    controller.push(still_scene(1.0, 2.0, (320, 240), np.random.default_rng(0)), None)
    assert controller.lux is None and metrics.totals["bias_switches"] == 0


def test_a_configured_lux_decides_at_the_start() -> None:
    metrics = EdgeMetrics()
    controller = BiasController(SensorConfig(lux=4.0), ReplayLike(), metrics, FACTORY)
    controller.begin()
    assert controller.state.profile == DARK and controller.lux == 4.0
    controller.push(still_scene(0.01, 2.0, (320, 240), np.random.default_rng(0)), None)  # events do not override it
    assert controller.lux == 4.0


class RoiReplayLike:
    """A replay whose sensor ROI the test moves: the controller reads ``roi`` as the edge's sources give it."""

    width, height = 640, 480

    def __init__(self) -> None:
        self.roi: tuple[int, int, int, int] = (0, 0, self.width, self.height)


def inside(events: Events, rect: tuple[int, int, int, int]) -> Events:
    x0, y0, w, h = rect
    keep = (events["x"] >= x0) & (events["x"] < x0 + w) & (events["y"] >= y0) & (events["y"] < y0 + h)
    return events[keep]


def test_tiles_read_out_for_part_of_a_slice_count_at_their_own_rate() -> None:
    # the whole sensor for 0.4 s (the gyroscope not yet trusted), then a ROI around the window: the
    # tiles outside it were read out 0.4 s of the 1-s slice and their rate is counts over that time
    source, rng = RoiReplayLike(), np.random.default_rng(5)
    controller = BiasController(SensorConfig(stride=1, settle_s=0.0), source, EdgeMetrics(), FACTORY)  # (no start-up burst)
    controller.begin()
    window, roi = (260, 200, 100, 80), (200, 140, 240, 200)
    rate = curve_rate(FACTORY, 8.0)
    for k in range(20):  # 50-ms chunks over 1 s, the page under the gaze firing hard
        chunk = still_scene(rate, 0.05, (640, 480), rng, t0_us=k * 50_000, edge_rect=roi, edge_rate_hz=40.0)
        if k == 8:
            source.roi = roi
        controller.push(chunk if k < 8 else inside(chunk, roi), window)
    controller.push(inside(still_scene(rate, 0.01, (640, 480), rng, t0_us=1_000_000), roi), window)
    assert controller.lux == pytest.approx(8.0, rel=0.2)


def test_a_roi_over_the_page_gives_no_estimate_rather_than_the_texts_edges() -> None:
    # a ROI through the whole slice: its tiles hold the page's moving text, which fires at any light;
    # a bright page read from them would read as dark (and switch the glasses to the dark profile)
    source, rng = RoiReplayLike(), np.random.default_rng(6)
    source.roi = (200, 140, 240, 200)
    controller = BiasController(SensorConfig(stride=1), source, EdgeMetrics(), FACTORY)
    controller.begin()
    for k in range(3):
        chunk = still_scene(curve_rate(FACTORY, 100.0), 1.0, (640, 480), rng, t0_us=k * 1_000_000,
                            edge_rect=source.roi, edge_rate_hz=1.0)
        controller.push(inside(chunk, source.roi), (260, 200, 100, 80))
    assert controller.lux is None and controller.state.profile == FACTORY


def test_through_a_roi_the_whole_sensor_is_asked_for_now_and_then_to_read_the_light() -> None:
    # the ROI on from the start (a still head, its gyroscope trusted): no light read, so at once (no
    # start-up burst to settle here) the controller asks for the whole sensor until one part is read,
    # then every probe_every_s for probe_s of it
    source, rng = RoiReplayLike(), np.random.default_rng(7)
    roi, window = (200, 140, 240, 200), (260, 200, 100, 80)
    config = SensorConfig(stride=1, probe_every_s=2.0, probe_s=0.3, settle_s=0.0)
    controller = BiasController(config, source, EdgeMetrics(), FACTORY)
    controller.begin()
    whole_s, asked = 0.0, []
    for k in range(100):  # 50-ms chunks over 5 s at 8 lux, the sensor following what the controller wants
        source.roi = (0, 0, 640, 480) if controller.wants_whole() else roi
        chunk = still_scene(curve_rate(FACTORY, 8.0), 0.05, (640, 480), rng, t0_us=k * 50_000, edge_rect=roi, edge_rate_hz=40.0)
        whole_s += 0.05 if source.roi == (0, 0, 640, 480) else 0.0
        controller.push(chunk if source.roi == (0, 0, 640, 480) else inside(chunk, roi), window)
        asked.append(controller.wants_whole())
    assert controller.lux == pytest.approx(8.0, rel=0.2)  # read in the probes
    starts = [k for k in range(1, 100) if asked[k] and not asked[k - 1]]
    # before the first estimate (at 1 s) until one 250-ms part is read, then probe_every_s after the estimate
    assert asked[0] and not asked[6] and starts == [60] and not asked[-1]
    assert 0.5 <= whole_s <= 0.7  # 250-300 ms at the start (50-ms chunks), about probe_s in the probe


def test_the_probe_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="probe_s between a quarter of estimate_s"):
        load_config(None, environ={}, overrides={"sensor": {"probe_s": 0.1}})
    assert load_config(None, environ={"DARKREAD_EDGE_SENSOR_PROBE_EVERY_S": "0"}).sensor.probe_every_s == 0


def test_recordings_name_their_profile_by_offsets() -> None:
    assert profile_named(profile_offsets(DARK)) == DARK
    assert profile_named({}) == FACTORY
    assert profile_named({"diff_on": 7}) is None and profile_named(None) is None


def test_a_page_filling_the_view_swept_by_the_head_reads_at_its_stillest_part() -> None:
    """A head moving over a page that fills the view sweeps text edges over every tile, but not all
    the time: the slice is read in parts and the stillest one gives the light. Read over the whole
    second (the parts' counts together), the 30-lux page would read as dark."""
    rng = np.random.default_rng(8)
    wh = (640, 480)
    rate = curve_rate(FACTORY, 30.0)
    controller = BiasController(SensorConfig(stride=1, settle_s=0.0), ReplayLike640(), EdgeMetrics(), FACTORY)
    controller.begin()
    chunks = []
    for k in range(21):  # 50-ms chunks; the head sweeps the page for 150 ms of every 250 but the last
        moving = k < 15 and k % 5 < 3
        chunks.append(still_scene(rate, 0.05, wh, rng, t0_us=k * 50_000, edge_rect=(0, 0) + wh if moving else None,
                                  edge_rate_hz=3.0))
    for chunk in chunks:
        controller.push(chunk, None)
    assert controller.lux is not None and controller.lux > 25.0  # bright: the factory profile stays
    assert controller.state.profile == FACTORY
    whole = np.sort(np.concatenate(chunks[:20]), order="t")
    assert estimate(whole, wh, 1.0, CURVES[FACTORY]) < 15.0  # the whole second at once: into the dark profile


class ReplayLike640:
    width, height = 640, 480


def test_the_streams_start_settles_and_the_first_reading_follows_at_once_through_a_roi() -> None:
    """A sensor that starts streaming fires hard for a while (the simulated one read a 30-lux page as
    1.6 lux in its first quarter second): those events are left out as after a bias write, and then,
    with no light read yet, the controller asks for the whole sensor at once, not after probe_every_s."""
    source, rng = RoiReplayLike(), np.random.default_rng(9)
    roi, window = (200, 140, 240, 200), (260, 200, 100, 80)
    controller = BiasController(SensorConfig(stride=1), source, EdgeMetrics(), FACTORY)  # settle_s 0.5, probe_s 0.3
    controller.begin()
    asked = []
    for k in range(40):  # 50-ms chunks over 2 s at 30 lux; the first 0.4 s a start-up burst; a ROI unless asked
        source.roi = (0, 0, 640, 480) if k < 4 or controller.wants_whole() else roi
        rate = curve_rate(FACTORY, 1.5 if k < 8 else 30.0)  # (the burst's rate: a dark room's)
        chunk = still_scene(rate, 0.05, (640, 480), rng, t0_us=k * 50_000, edge_rect=roi, edge_rate_hz=40.0)
        controller.push(chunk if source.roi == (0, 0, 640, 480) else inside(chunk, roi), window)
        asked.append(controller.wants_whole())
    assert controller.lux is not None and controller.lux > 25.0 and controller.state.profile == FACTORY
    assert not any(asked[:9]) and any(asked[10:12]) and not asked[-1]  # asked once settled (0.5 s), given back once read


def test_the_sensor_is_given_back_to_the_roi_once_the_first_estimate_is_made() -> None:
    """However the first part and the slice end (here a slice of one part: its rate and the estimate
    come in the same chunk), the start's wish for the whole sensor ends with the first estimate."""
    source, rng = RoiReplayLike(), np.random.default_rng(10)
    roi, window = (200, 140, 240, 200), (260, 200, 100, 80)
    config = SensorConfig(stride=1, settle_s=0.0, estimate_s=0.25, probe_s=0.25, probe_every_s=60.0)
    controller = BiasController(config, source, EdgeMetrics(), FACTORY)
    controller.begin()
    whole_s = 0.0
    for k in range(40):  # 50-ms chunks over 2 s at 8 lux, the sensor following what the controller wants
        source.roi = (0, 0, 640, 480) if controller.wants_whole() or k == 0 else roi
        chunk = still_scene(curve_rate(FACTORY, 8.0), 0.05, (640, 480), rng, t0_us=k * 50_000, edge_rect=roi, edge_rate_hz=40.0)
        whole_s += 0.05 if source.roi == (0, 0, 640, 480) else 0.0
        controller.push(chunk if source.roi == (0, 0, 640, 480) else inside(chunk, roi), window)
    assert controller.lux == pytest.approx(8.0, rel=0.2)
    assert not controller.wants_whole() and whole_s <= 0.35  # one part (and the chunk that ended it), then the ROI
