"""`darkread eval compare-simulators`: the same recordings made by two simulators, CER per lux side by side."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from darkread.cli import main
from darkread.lab.eval.simulators import simulator_section

# name -> (lux, motion, CER on our simulator's recording, CER on the second one's)
CERS = {"037_lux10_still_words": (10.0, "still", 0.10, 0.30), "043_lux10_normal_paragraph": (10.0, "normal", 0.20, 0.60),
        "049_lux5_still_words": (5.0, "still", 0.40, 1.70)}  # 1.7: clipped at 100 % before the mean


def _suite(root: Path, simulator: str, column: int, rate: float) -> Path:
    for name, row in CERS.items():
        lux, motion = row[0], row[1]
        (root / name).mkdir(parents=True)
        (root / name / "text.txt").write_text("a text")
        (root / name / "meta.json").write_text(json.dumps({"simulator": simulator, "event_rate_hz": rate * lux}))
        run = root / "eval_runs" / "every-window" / name
        run.mkdir(parents=True)
        doc = {"name": name, "lux": lux, "motion": motion, "kind": "words", "infer": "every-window",
               "darkread": {"text": "x", "cer": row[column], "wer": row[column]}}
        (run / "result.json").write_text(json.dumps(doc))
    return root


def test_compare_simulators_pairs_recordings_by_name_and_means_cer_per_lux(tmp_path: Path, capsys) -> None:
    ours = _suite(tmp_path / "ours", "darkread", 2, 100_000.0)
    theirs = _suite(tmp_path / "hesim", "hesim", 3, 50_000.0)
    out = tmp_path / "report"
    assert main(["eval", "compare-simulators", str(ours), str(theirs), "--out", str(out), "--infer", "every-window"]) == 0
    md = (out / "simulators.md").read_text()
    assert "| **all** | 3 |" in capsys.readouterr().out  # printed too
    assert "| lux | n | CER, `darkread` events | CER, `hesim` events | `hesim` − `darkread` |" in md
    assert "| 5 | 1 | 40.0% | 100.0% | +60.0 pp | 500 k/s | 250 k/s |" in md
    assert "| 10 | 2 | 15.0% | 45.0% | +30.0 pp | 1,000 k/s | 500 k/s |" in md
    assert "| **all** | 3 | 23.3% | 63.3% | +40.0 pp |" in md
    assert "| 10, normal | 1 | 20.0% | 60.0% | +40.0 pp |" in md

    # the report written into that folder shows it as its "Second simulator" section
    section = simulator_section(out)
    assert section[0] == "## Second simulator" and "| 5 | 1 | 40.0% | 100.0% | +60.0 pp | 500 k/s | 250 k/s |" in section
    assert not any(line.startswith("# ") for line in section) and simulator_section(tmp_path / "nowhere") == []


def test_compare_simulators_wants_two_evaluated_suites(tmp_path: Path, capsys) -> None:
    ours = _suite(tmp_path / "ours", "darkread", 2, 1.0)
    with pytest.raises(SystemExit) as usage:  # argparse names the missing suite, with the form's usage
        main(["eval", "compare-simulators", str(ours)])
    assert usage.value.code == 2 and "OTHER_SUITE" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["eval", "compare-simulators", str(ours), str(tmp_path / "empty"), "--out", str(tmp_path / "x.md")]) == 1
    err = capsys.readouterr().err
    assert "no stored results" in err and err.count("\n") == 1
