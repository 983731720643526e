from __future__ import annotations

import numpy as np
import pytest
from reading_factory import ScanParams, simulate_reading

from darkread.core.frame_record import FrameRecord
from darkread.stitch import LineSegmenter, StitchConfig, segment_lines


def _frames(gaze: list[tuple[float, float]]) -> list[FrameRecord]:
    blank = np.zeros((100, 200), np.uint8)
    return [FrameRecord(i, i * 40_000, blank, (int(u) - 100, int(v) - 50), (u, v)) for i, (u, v) in enumerate(gaze)]


def _line(x0: float, x1: float, y: float, rng: np.random.Generator, per_fix: int = 3) -> list[tuple[float, float]]:
    xs = np.arange(x0, x1, 70.0)
    return [(x + rng.normal(0, 20), y + rng.normal(0, 20)) for x in xs for _ in range(per_fix)]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_lines_of_a_simulated_reading_match_the_text_lines(rendered_page, seed: int) -> None:
    reading = simulate_reading(rendered_page, seed=seed)
    line_of = {f.frame_id: li for f, li in zip(reading.frames, reading.line_of_frame)}
    lines = segment_lines(reading.frames)
    assert [sorted({line_of[f.frame_id] for f in line}) for line in lines] == [
        [i] for i in range(len(rendered_page.text_lines))
    ]


def test_heavy_gaze_noise_still_gives_one_segment_per_line(rendered_page) -> None:
    reading = simulate_reading(rendered_page, ScanParams(gaze_noise_px=25.0, fixation_bias_px=12.0), seed=5)
    line_of = {f.frame_id: li for f, li in zip(reading.frames, reading.line_of_frame)}
    lines = segment_lines(reading.frames)
    assert len(lines) == len(rendered_page.text_lines)
    purity = np.mean([max(np.bincount([line_of[f.frame_id] for f in line])) / len(line) for line in lines])
    assert purity > 0.97


def test_regressions_stay_in_the_line() -> None:
    rng = np.random.default_rng(0)
    gaze = _line(100, 300, 200, rng) + [(220.0, 200.0)] * 3 + _line(300, 600, 200, rng)
    assert len(segment_lines(_frames(gaze))) == 1


def test_undershooting_return_sweep_with_corrective_saccade_is_one_break() -> None:
    rng = np.random.default_rng(1)
    first = _line(100, 600, 200, rng)
    undershoot = [(230.0 + rng.normal(0, 15), 228.0 + rng.normal(0, 15)) for _ in range(2)]
    second = _line(120, 600, 228, rng)
    lines = segment_lines(_frames(first + undershoot + second))
    assert [len(line) for line in lines] == [len(first), len(undershoot) + len(second)]


def test_a_single_wild_gaze_sample_does_not_break_the_line() -> None:
    rng = np.random.default_rng(2)
    first, rest = _line(100, 400, 200, rng), _line(400, 600, 200, rng)
    assert len(segment_lines(_frames(first + [(90.0, 210.0)] + rest))) == 1


def test_jumping_back_up_to_an_earlier_line_is_not_a_return_sweep() -> None:
    rng = np.random.default_rng(3)
    gaze = _line(100, 600, 300, rng) + _line(150, 400, 200, rng)
    assert len(segment_lines(_frames(gaze))) == 1


def test_streaming_decisions_equal_batch_and_lag_by_the_confirmation(reading) -> None:
    cfg = StitchConfig()
    segmenter = LineSegmenter(cfg)
    decided = []
    for i, frame in enumerate(reading.frames):
        decided += segmenter.push(frame)
        assert len(decided) == max(0, i + 1 - cfg.sweep_confirm_frames)
    decided += segmenter.flush()
    breaks = [f.frame_id for f, new in decided if new]
    assert breaks == [line[0].frame_id for line in segment_lines(reading.frames, cfg)]


def test_segmentation_partitions_any_gaze_track_in_order() -> None:
    from hypothesis import given, settings
    from hypothesis import strategies as st

    coords = st.tuples(st.floats(0, 1280, allow_nan=False), st.floats(0, 720, allow_nan=False))

    @settings(max_examples=60, deadline=None)
    @given(st.lists(coords, max_size=60), st.integers(0, 4))
    def check(gaze: list[tuple[float, float]], confirm: int) -> None:
        frames = _frames(gaze)
        cfg = StitchConfig(sweep_confirm_frames=confirm)
        lines = segment_lines(frames, cfg)
        assert [f.frame_id for line in lines for f in line] == [f.frame_id for f in frames]
        assert all(lines)
        assert all(len(line) >= cfg.min_line_frames for line in lines[:-1])

    check()
