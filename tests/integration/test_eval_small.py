"""CI's look at the evaluation: the first recordings of the small suite, made, read and reported
through the command line exactly as `darkread eval` runs the full suite."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from darkread.cli import main

pytestmark = pytest.mark.slow

MAX_BRIGHT_CER = 0.15  # 1000 lux, normal motion, pangram: darkread reads it (regression guard)


def test_small_suite_subset_is_made_read_and_reported(tmp_path: Path) -> None:
    suite, report = tmp_path / "suite", tmp_path / "report"
    assert main(["eval", "make-suite", str(suite), "--small", "--limit", "2", "--jobs", "2"]) == 0
    assert main(["eval", "run", str(suite), "--out", str(report), "--jobs", "2", "--compare", "rapidocr", "rapidocr-raw"]) == 0

    results = json.loads((report / "results.json").read_text())
    assert [r["lux"] for r in results] == [1000.0, 100.0]
    for r in results:
        for section in ("darkread", "rgb", "bandwidth"):
            assert "error" not in r[section], (r["name"], section, r[section])
        assert set(r["backends"]) == {"rapidocr", "rapidocr-raw"}
        assert r["duration_s"] < 1.0 + 2.5 * 3  # read once: it ends before the cap
    bright = results[0]
    assert bright["darkread"]["cer"] <= MAX_BRIGHT_CER, bright["darkread"]["text"]
    assert bright["rgb"]["cer"] <= MAX_BRIGHT_CER, bright["rgb"]["text"]  # a bright photo reads too

    md = (report / "README.md").read_text()
    for heading in ("## Paragraphs at 30 lux", "## CER vs light", "## Bandwidth", "## The RGB baseline", "## Per recording"):
        assert heading in md, heading
    for png in ("cer_vs_lux.png", "cer_vs_lux_by_motion.png", "cer_vs_xheight.png", "ocr_backends_by_kind.png"):
        assert (report / png).read_bytes()[:4] == b"\x89PNG", png
