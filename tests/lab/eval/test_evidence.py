"""How much ink the events show: the scores on known arrays, and a synthetic recording scored end to end."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.events import EVENT_CD_DTYPE
from darkread.lab.eval.evidence import Evidence, count_image, evidence_table, ink_and_paper_scores, recording_evidence, separability


def test_separability_is_the_chance_a_positive_beats_a_negative() -> None:
    assert separability(np.array([3.0, 4.0]), np.array([1.0, 2.0])) == 1.0
    assert separability(np.array([1.0]), np.array([2.0])) == 0.0
    assert separability(np.array([2.0, 2.0]), np.array([2.0])) == 0.5  # ties count half
    assert separability(np.array([1.0, 3.0]), np.array([2.0])) == 0.5
    assert np.isnan(separability(np.array([]), np.array([1.0])))
    rng = np.random.default_rng(0)
    assert abs(separability(rng.normal(size=4000), rng.normal(size=4000)) - 0.5) < 0.02


def test_count_image_counts_each_pixels_events_and_ignores_the_outside() -> None:
    ev = np.zeros(4, EVENT_CD_DTYPE)
    ev["x"], ev["y"] = [10, 10, 11, 300], [5, 5, 6, 5]
    counts = count_image(ev, (0, 0), (100, 200))
    assert counts[5, 10] == 2 and counts[6, 11] == 1 and counts.sum() == 3


def test_ink_pixels_with_events_on_them_separate_from_paper() -> None:
    ink = np.zeros((100, 200), np.uint8)
    ink[40:60, 50:52] = 1  # a vertical stroke
    counts = np.zeros((100, 200), np.float32)
    counts[40:60, 50:52] = 3.0
    on_ink, on_paper = ink_and_paper_scores(counts, ink)
    assert on_ink.size == 40 and on_paper.size == 100 * 200 - 26 * 8  # paper: 3 px or more from the stroke
    assert separability(on_ink, on_paper) == 1.0
    assert separability(*ink_and_paper_scores(np.ones((100, 200), np.float32), ink)) == 0.5  # events everywhere


def test_the_table_groups_by_lux_and_motion() -> None:
    def row(lux: float, motion: str, s: float) -> Evidence:
        return Evidence(f"{lux}{motion}", lux, motion, 3, {"measured/1600": s, "exact/1600": s + 0.1},
                        {"measured/1600": s / 2, "exact/1600": 0.0})

    lines = evidence_table([row(10.0, "still", 0.8), row(10.0, "walking", 0.6), row(5.0, "still", 0.5)], lengths=(1600,))
    assert lines[0].count("|") == 7 and "| 10 | **all** | 2 | 0.700 | 0.800 | 35% |" in lines
    assert lines.index("| 10 | **all** | 2 | 0.700 | 0.800 | 35% |") < lines.index("| 5 | still | 1 | 0.500 | 0.600 | 25% |")


@pytest.mark.timeout(300)
def test_a_synthetic_recordings_events_show_its_ink(tmp_path) -> None:
    """In bright light with a still head the events lie on the strokes: ink and paper separate almost
    perfectly, and the exact motion is no worse than the measured one."""
    from darkread.models.synth.recording import RecordingSpec, write_recording

    spec = RecordingSpec(lux=100.0, motion="still", kind="words", seconds=0.7, seed=11, xheight_px=10.0, n_lines=3,
                         line_chars=22)
    rec = tmp_path / "suite" / "still"
    write_recording(rec, spec, progress=False)
    row = recording_evidence(rec, lengths=(1600, 3200), every_ms=40.0, max_windows=6)
    assert row is not None and row.lux == 100.0 and row.motion == "still" and row.windows >= 3
    assert set(row.separability) == {"measured/1600", "measured/3200", "exact/1600", "exact/3200"}
    assert min(row.separability.values()) > 0.9 and row.coverage["measured/1600"] > 0.8

    from darkread.cli import main

    (rec / "text.txt").write_text("a suite of one", encoding="utf-8")
    assert main(["eval", "evidence", str(tmp_path / "suite"), "--out", str(tmp_path / "e.md")]) == 0
    report = (tmp_path / "e.md").read_text(encoding="utf-8")
    assert "| 100 | still | 1 |" in report and (tmp_path / "e.json").is_file()
    assert main(["eval", "evidence", str(tmp_path / "missing")]) == 1  # one error line, not a traceback


def test_a_recording_without_the_simulators_truth_has_no_evidence(tiny_recording, capsys) -> None:
    from darkread.cli import main

    assert recording_evidence(tiny_recording) is None
    assert main(["eval", "evidence", str(tiny_recording.parent), "--out", str(tiny_recording.parent / "e.md")]) == 1
    assert "no recording carries the simulator's truth" in capsys.readouterr().err
