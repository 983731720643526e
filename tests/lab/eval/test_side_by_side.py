"""``darkread eval side-by-side``: suites of the same scenes compared row by row on the recordings they share."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from darkread.lab.eval.side_by_side import LabelledSuite, cer_rows, write_side_by_side


def _result(name: str, lux: float, motion: str, cer: float, rgb: float | None = None) -> dict[str, Any]:
    doc: dict[str, Any] = {"name": name, "lux": lux, "motion": motion, "kind": "words", "font": "DejaVu Sans",
                           "held_out_font": False, "xheight_px": 10.0, "duration_s": 2.0,
                           "darkread": {"text": "x", "cer": cer, "wer": cer}}
    if rgb is not None:
        doc["rgb"] = {"text": "", "cer": rgb, "wer": rgb}
    return doc


def _suite(root: Path, docs: list[dict[str, Any]]) -> Path:
    for doc in docs:
        folder = root / "eval_runs" / "on-change" / doc["name"]
        folder.mkdir(parents=True)
        (folder / "result.json").write_text(json.dumps(doc))
    return root


@pytest.fixture
def suites(tmp_path: Path) -> list[LabelledSuite]:
    grounded = _suite(tmp_path / "g", [_result("048_lux5_still", 5.0, "still", 0.30, rgb=1.0),
                                       _result("049_lux5_normal", 5.0, "normal", 0.50, rgb=1.0),
                                       _result("024_lux30_still", 30.0, "still", 0.02, rgb=0.2)])
    dark = _suite(tmp_path / "d", [_result("048_lux5_still", 5.0, "still", 0.10),
                                   _result("049_lux5_normal", 5.0, "normal", 0.20)])
    return [LabelledSuite.load(f"factory={grounded}", "on-change"), LabelledSuite.load(f"dark={dark}", "on-change")]


def test_rows_compare_the_recordings_all_holding_suites_share(suites: list[LabelledSuite]) -> None:
    rows = cer_rows(suites, "lux", "lux", reference="factory")
    assert rows[0] == "| lux | n | factory | dark | dark − factory (points) | RGB |"
    assert rows[2] == "| 5 | 2 | 40.0% | 15.0% | -25.0 | 100.0% |"
    assert rows[3] == "| 30 | 1 | 2.0% | – | – | 20.0% |"  # only one suite holds 30 lux
    motion = cer_rows(suites, ("lux", "motion"), "lux, motion")
    assert "| 5, normal | 1 | 50.0% | 20.0% | 100.0% |" in motion


def test_the_page_has_both_tables_the_plot_and_the_command(suites: list[LabelledSuite], tmp_path: Path) -> None:
    out = write_side_by_side(suites, tmp_path / "out" / "band.md", title="Dark profile", reference="dark",
                             command="darkread eval side-by-side ...")
    text = out.read_text()
    assert "## By light and motion" in text and "darkread eval side-by-side ..." in text
    assert (tmp_path / "out" / "band.png").stat().st_size > 1000


def test_a_wrong_label_or_folder_is_one_clear_error(suites: list[LabelledSuite], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="LABEL=SUITE_DIR"):
        LabelledSuite.load(str(tmp_path), "on-change")
    with pytest.raises(FileNotFoundError, match="darkread eval run"):
        LabelledSuite.load(f"x={tmp_path / 'nothing'}", "on-change")
    with pytest.raises(ValueError, match="--reference 'rgb'"):
        write_side_by_side(suites, tmp_path / "x.md", title="t", reference="rgb")
    with pytest.raises(ValueError, match="labels must differ"):
        write_side_by_side([suites[0], suites[0]], tmp_path / "x.md", title="t")


def test_the_command_line_writes_the_page(suites: list[LabelledSuite], tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    from darkread.cli import main

    out = tmp_path / "cli.md"
    assert main(["eval", "side-by-side", f"a={tmp_path / 'g'}", f"b={tmp_path / 'd'}", "--out", str(out)]) == 0
    assert out.is_file() and "2 suites side by side" in capsys.readouterr().out
    assert main(["eval", "side-by-side", "nolabel", "--out", str(out)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "LABEL=SUITE_DIR" in err[0]
