"""Re-stitching stored frames: placements checked against the truth through the map between the pages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from darkread.lab.eval.restitch import MISPLACED_PX, Restitched, placement_errors, restitch_table, write_restitch


def test_placement_errors_are_what_is_left_after_the_map_between_the_pages() -> None:
    rng = np.random.default_rng(0)
    true = {i: rng.uniform(0, 400, 2) for i in range(12)}
    shapes = {i: (100, 200) for i in true}
    # the stitched page: the true page at 0.8 of its scale, moved; frame 5 stitched 20 px off
    placed = {i: (0.8 * c[0] + 30 - 100, 0.8 * c[1] - 12 - 50) for i, c in true.items()}
    placed[5] = (placed[5][0] + 20, placed[5][1])
    errors = placement_errors(placed, shapes, true)
    assert errors.shape == (12,)
    assert errors[5] > 15 and np.median(errors) < 2.5
    assert int((errors > MISPLACED_PX).sum()) == 1
    assert placement_errors({0: (0.0, 0.0)}, shapes, true).size == 0  # too few frames for a map


def test_the_table_groups_by_light_and_motion_with_the_run_before() -> None:
    rows = [Restitched("a", 30.0, "still", 10, 0.1, 0.0, 1.0, 0, lines=((0.0, 20, True), (0.1, 30, True))),
            Restitched("b", 30.0, "walking", 8, 0.5, 0.25, 2.0, 3, lines=((0.5, 20, False), (0.2, 10, True)))]
    before = {"a": {"cer": 0.1, "misplaced": 0}, "b": {"cer": 0.5, "misplaced": 6}}
    table = restitch_table(rows, before)
    # answered: 3 of 4 lines, their CER (0 * 20 + 0.1 * 30 + 0.2 * 10) / 60
    assert "| 30 | **all** | 2 | 30.0% | 12.5% | 30.0% | 1.5 | 3 of 18 | 6 | 75.0% | 8.3% |" in table
    assert "| 30 | walking | 1 | 50.0% | 25.0% | 50.0% | 2.0 | 3 of 8 | 6 | 50.0% | 20.0% |" in table
    assert "before" not in restitch_table(rows)


def test_a_suite_without_stored_frames_or_a_wrong_before_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="darkread eval run"):
        write_restitch(tmp_path, tmp_path / "work", tmp_path / "out.md", progress=False)
    run = tmp_path / "work" / "rec"
    (run / "read" / "cloud").mkdir(parents=True)
    (tmp_path / "before.json").write_text(json.dumps({"not": "rows"}))
    with pytest.raises(ValueError, match="an earlier `darkread eval restitch` wrote"):
        write_restitch(tmp_path, tmp_path / "work", tmp_path / "out.md", before=tmp_path / "before.json", progress=False)
