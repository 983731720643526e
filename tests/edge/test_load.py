"""What a live edge that falls behind gives up (edge.load): the pure decision and its state."""

from __future__ import annotations

import logging

from darkread.edge.load import LEVELS, LoadShedder, ShedConfig, frames_per_view, overlap_share, shed_level, skip_covered

CFG = ShedConfig(high_lag_s=0.1, low_lag_s=0.02, calm_steps=3)


def test_a_long_wait_sheds_one_level_more_up_to_the_last() -> None:
    assert shed_level(0.1, 0, 5, CFG) == (1, 0)
    assert shed_level(0.5, 1, 0, CFG) == (2, 0)
    assert shed_level(0.5, len(LEVELS) - 1, 0, CFG) == (len(LEVELS) - 1, 0)


def test_a_middling_wait_holds_the_level_and_breaks_the_calm() -> None:
    assert shed_level(0.05, 1, 2, CFG) == (1, 0)
    assert shed_level(0.05, 0, 2, CFG) == (0, 0)


def test_a_level_is_given_back_only_after_a_run_of_prompt_steps() -> None:
    level, calm = 2, 0
    seen = []
    for _ in range(7):
        level, calm = shed_level(0.001, level, calm, CFG)
        seen.append(level)
    assert seen == [2, 2, 1, 1, 1, 0, 0]
    assert shed_level(0.001, 0, 10, CFG) == (0, 11)  # nothing to give back: the run just grows


def test_the_levels_cap_a_views_frames_never_below_one() -> None:
    assert [frames_per_view(level) for level in range(len(LEVELS))] == [None, 2, 1, 1]


def test_the_overlap_is_the_share_of_the_window_inside_the_other() -> None:
    window = (100, 50, 200, 100)
    assert overlap_share(window, window) == 1.0
    assert overlap_share(window, (200, 50, 200, 100)) == 0.5  # half a window along the line
    assert overlap_share(window, (150, 100, 200, 100)) == 0.75 * 0.5
    assert overlap_share(window, (300, 50, 200, 100)) == 0.0  # touching
    assert overlap_share(window, (0, 0, 1280, 720)) == 1.0


def test_only_the_last_level_skips_a_fixation_the_last_view_covers() -> None:
    last = (100, 50, 200, 100)
    covered, moved_on = (160, 60, 200, 100), (220, 50, 200, 100)
    assert [skip_covered(level, covered, last) for level in range(len(LEVELS))] == [False, False, False, True]
    assert not skip_covered(len(LEVELS) - 1, moved_on, last)  # 40 % inside: a view of its own
    assert not skip_covered(len(LEVELS) - 1, covered, None)  # no view yet


def test_the_shedder_logs_each_change(caplog) -> None:
    shedder = LoadShedder(CFG)
    with caplog.at_level(logging.INFO, logger="darkread.edge.load"):
        changes = [shedder.observe(lag) for lag in (0.2, 0.2, 0.2, 0.0, 0.0, 0.0)]
    assert changes == [True, True, True, False, False, True] and shedder.level == len(LEVELS) - 2
    assert "falling behind (a step waited 200 ms): shedding, a view's frames capped" in caplog.text
    assert "falling behind (a step waited 200 ms): shedding, one frame per view, and none where" in caplog.text
    assert "keeping up again: shedding one frame per view\n" in caplog.text
