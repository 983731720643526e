from __future__ import annotations

import json

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.events import EVENT_CD_DTYPE
from darkread.edge.gaze import GazeMapper
from darkread.edge.io.calibration import load_calibration
from darkread.edge.io.gaze_csv import read_gaze_csv
from darkread.edge.io.raw import read_raw
from darkread.models.synth.recording import RecordingSpec, add_gyroscope, write_recording
from darkread.models.synth.session import SessionSpec, make_session

SPEC = RecordingSpec(lux=200.0, motion="still", kind="pangram", seconds=0.4, seed=5, xheight_px=8.0, n_lines=3, line_chars=22)


def test_short_recording_round_trips_and_gaze_lands_on_text(tmp_path):
    meta = write_recording(tmp_path, SPEC, progress=False)
    assert set(meta) >= {
        "description", "lux", "motion", "text_kind", "font", "xheight_px", "xheight_px_measured_t0", "duration_s",
        "text_source", "n_lines", "event_count", "event_rate_hz",
    }
    assert json.loads((tmp_path / "meta.json").read_text())["event_count"] == meta["event_count"]

    raw = read_raw(tmp_path / "events.raw")
    ev = raw.events
    assert ev.size == meta["event_count"] > 1000
    assert np.all(np.diff(ev["t"]) >= 0)
    assert raw.header.width == 1280 and raw.header.height == 720
    key = ev["t"] * (1280 * 720) + ev["y"].astype(np.int64) * 1280 + ev["x"]
    assert np.unique(key).size == ev.size  # no pixel fires twice in one microsecond

    text = (tmp_path / "text.txt").read_text()
    assert not text.endswith("\n") and len(text.split("\n")) == meta["n_lines"] == 3

    calib = load_calibration(tmp_path / "calibration.json")
    track = read_gaze_csv(tmp_path / "general_eye_gaze.csv")
    rate = (len(track) - 1) / ((track.t_us[-1] - track.t_us[0]) * 1e-6)
    assert 50 < rate < 65
    assert np.all(track.depth_m[np.isfinite(track.depth_m)] <= 4.0)

    # gaze, mapped through the files alone, lands on the printed text (within tracker error)
    mapper = GazeMapper(calib, track)
    t_events = ev["t"][:: max(1, ev.size // 200)]
    uv = mapper.pixels_at(t_events)
    ok = np.all(np.isfinite(uv), axis=1)
    assert ok.mean() > 0.8
    session = make_session(
        SessionSpec(lux=SPEC.lux, motion=SPEC.motion, kind=SPEC.kind, xheight_px=SPEC.xheight_px, n_lines=3,
                    line_chars=22, duration_s=SPEC.seconds),
        SPEC.seed,
    )
    x0, y0, x1, y1 = session.page.text_box
    corners = session.scene.project(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), 0.0)
    margin = 3.0 * calib.fx * np.tan(np.radians(1.0))  # ~3 deg of tracker error
    lo, hi = corners.min(axis=0) - margin, corners.max(axis=0) + margin
    inside = np.all((uv[ok] >= lo) & (uv[ok] <= hi), axis=1)
    assert inside.mean() > 0.8

    # the text region is busier than the rest of the sensor
    cx, cy = corners.mean(axis=0)
    near = (np.abs(ev["x"] - cx) < 60) & (np.abs(ev["y"] - cy) < 20)
    density_near = near.sum() / (120 * 40)
    density_all = ev.size / (1280 * 720)
    assert density_near > 5 * density_all


def test_recording_is_deterministic_for_a_seed(tmp_path):
    spec = RecordingSpec(lux=50.0, motion="normal", kind="words", seconds=0.1, seed=9, xheight_px=6.0, n_lines=3, line_chars=20)
    write_recording(tmp_path / "a", spec, progress=False)
    write_recording(tmp_path / "b", spec, progress=False)
    for name in ("events.raw", "general_eye_gaze.csv", "calibration.json", "text.txt"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_read_once_recording_ends_after_the_last_line_on_unseen_text(tmp_path):
    from dataclasses import replace

    from darkread.models.synth.recording import READ_ONCE_TAIL_S, recording_seconds, session_spec
    from darkread.models.synth.text import paragraphs_for

    spec = RecordingSpec(lux=200.0, motion="still", kind="paragraph", seconds=30.0, seed=3, xheight_px=8.0,
                         n_lines=2, line_chars=16, split="val", read_once=True)
    session = make_session(session_spec(spec), spec.seed)
    seconds = recording_seconds(spec, session)
    assert seconds == session.scanpath.first_pass_end_s() + READ_ONCE_TAIL_S < 5.0
    assert recording_seconds(replace(spec, read_once=False), session) == 30.0
    first_words = session.page.lines[0].split()[:2]
    assert any(" ".join(first_words) in " ".join(p.split()) for p in paragraphs_for("val"))
    meta = write_recording(tmp_path, replace(spec, seconds=0.5), progress=False)  # the cap bounds a read-once recording
    assert meta["text_split"] == "val" and meta["duration_s"] == 0.5


def test_a_recording_made_before_the_gyroscope_gets_the_one_it_would_carry_now(tmp_path):
    write_recording(tmp_path, SPEC)
    imu = tmp_path / "closed_loop_trajectory.csv"
    made = imu.read_bytes()
    others = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p != imu}
    imu.unlink()
    assert add_gyroscope(tmp_path, SPEC) == imu and imu.read_bytes() == made
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p != imu} == others


def test_full_view_recording_simulates_the_page_its_edge_and_a_desk_over_the_whole_sensor(tmp_path):
    spec = RecordingSpec(lux=100.0, motion="normal", seconds=0.06, seed=46, font="DejaVu Sans", xheight_px=10.0,
                         n_lines=22, line_chars=80, full_view=True)
    meta = write_recording(tmp_path / "view", spec, progress=False)
    assert meta["full_view"] is True and meta["simulated_region_xywh"] == [0, 0, 1280, 720]
    events = read_raw(tmp_path / "view" / "events.raw").events
    # signal everywhere, not only where the gaze goes: every quarter of the sensor sees the moving page or desk
    for x0, y0 in ((0, 0), (640, 0), (0, 360), (640, 360)):
        inside = (events["x"] >= x0) & (events["x"] < x0 + 640) & (events["y"] >= y0) & (events["y"] < y0 + 360)
        assert np.count_nonzero(inside) > 0.1 * events.size / 4
    session = make_session(SessionSpec(full_view=True, lux=100.0, motion="normal", n_lines=22, line_chars=80, xheight_px=10.0,
                                       font="DejaVu Sans"), 46)
    desk = session.scene.surround
    assert desk is not None and 0.02 <= desk.texture.min() < desk.texture.max() <= 0.95
    # without the option the scene is as it always was: no desk
    assert make_session(SessionSpec(lux=100.0, motion="normal"), 46).scene.surround is None


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sizes=st.lists(st.integers(0, 600), min_size=1, max_size=3),
       span_us=st.integers(1, 400), window=st.integers(1, 300), unsorted=st.booleans())
def test_merging_a_stretch_of_time_at_a_time_gives_the_same_events(seed: int, sizes: list[int], span_us: int,
                                                                   window: int, unsorted: bool) -> None:
    """A minute of a busy page held every event several times over while the duplicates were sorted
    out; a stretch at a time gives the very same array (same-microsecond events of one pixel
    across the parts: the first part's is kept), and a part out of time order is sorted whole."""
    from darkread.models.synth.recording import drop_same_time_duplicates, merged_events
    from darkread.models.synth.sensor import concat_events

    rng = np.random.default_rng(seed)
    parts = []
    for n in sizes:  # few pixels and microseconds: many duplicates, within and across the parts
        ev = np.zeros(n, EVENT_CD_DTYPE)
        ev["t"], ev["x"] = rng.integers(0, span_us, n), rng.integers(0, 6, n)
        ev["y"], ev["p"] = rng.integers(0, 3, n), rng.integers(0, 2, n)
        parts.append(ev if unsorted and n % 2 else ev[np.argsort(ev["t"], kind="stable")])
    expected = drop_same_time_duplicates(concat_events(parts))
    np.testing.assert_array_equal(merged_events(parts, events_per_window=window), expected)
