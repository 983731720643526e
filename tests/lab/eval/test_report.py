from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from PIL import Image

from darkread.lab.eval.provenance import ReportInfo
from darkread.lab.eval.report import write_report
from darkread.lab.eval.results import RecordingResult, typed
from darkread.lab.eval.tables import bandwidth_table, grouped_table, headline_table


def _bandwidth(png: int, frames_bytes: int, page: int) -> dict[str, Any]:
    return {
        "recording": "r", "duration_s": 2.0,
        "rgb": {"raw": 24_883_200, "png": png, "jpeg100": png // 2, "jpeg80": png // 10, "jpeg60": png // 20,
                "jpeg40": png // 30, "jpeg20": png // 40},
        "events": 1_000_000, "evt3_bytes": 4_000_000, "events_foveated": 20_000, "foveated_evt3_bytes": 90_000,
        "frames": 300, "frame_stream_bytes": frames_bytes, "page_bytes": page, "frames_measured": True,
        "rgb_wh": [2880, 2880],
    }


def fake_results() -> list[dict[str, Any]]:
    """Two recordings with given outcomes: darkread reads both, the RGB snapshot fails in the dark."""
    common = {"kind": "pangram", "font": "DejaVu Sans", "held_out_font": False, "duration_s": 2.0, "backend": "local"}
    return [
        {**common, "name": "000_bright", "lux": 1000.0, "motion": "still", "xheight_px": 10.0,
         "darkread": {"text": "the quick fox", "cer": 0.02, "wer": 0.10},
         "rgb": {"text": "the quick fox", "cer": 0.0, "wer": 0.0, "exposure_ms": 11.8, "gain": 1.0,
                 "paper_electrons": 1000.0, "blur_px": 1.0},
         "backends": {"rapidocr": {"cer": 0.02, "wer": 0.1}, "tesseract": {"cer": 0.10, "wer": 0.3}},
         "bandwidth": _bandwidth(png=20_000_000, frames_bytes=2_000_000, page=10_000)},
        {**common, "name": "001_dark", "lux": 5.0, "motion": "walking", "xheight_px": 8.0, "font": "Roboto",
         "held_out_font": True,
         "darkread": {"text": "the quick fix", "cer": 0.06, "wer": 0.30},
         "rgb": {"text": "", "cer": 1.0, "wer": 1.0, "exposure_ms": 33.3, "gain": 16.0,
                 "paper_electrons": 12.5, "blur_px": 15.0},
         "backends": {"rapidocr": {"cer": 0.06, "wer": 0.3}, "tesseract": {"error": "OcrError: boom"}},
         "bandwidth": _bandwidth(png=18_000_000, frames_bytes=1_000_000, page=8_000)},
    ]


def test_rate_reads_nested_sections_and_clips() -> None:
    r = RecordingResult.from_dict({"darkread": {"cer": 1.7}, "backends": {"x": {"cer": 0.25}}, "rgb": {"error": "no"}})
    assert r.rate("darkread") == 1.0
    assert r.backend_rate("x") == 0.25
    assert r.rate("rgb") is None and r.backend_rate("y") is None
    assert r.failures == ("rgb: no",)


def test_grouped_table_means_per_lux() -> None:
    rows = grouped_table(typed(fake_results()), "lux", "lux", lambda v: f"{v:g}")
    assert rows[2] == "| 5 | 1 | 6.0% | 30.0% | 100.0% | 100.0% |"
    assert rows[3] == "| 1000 | 1 | 2.0% | 10.0% | 0.0% | 0.0% |"


def test_bandwidth_table_medians_and_paper_ratios() -> None:
    text = "\n".join(bandwidth_table(typed(fake_results())))
    assert "one full image of 2880 x 2880 pixels" in text
    # medians: PNG 19 MB; frames 1.5 MB per page = 750 kB/s; page 9 kB
    assert "| RGB snapshot, PNG | 19.0 MB | – | 1.0x |" in text
    assert "| `every-window`: binary frames as sent (Frame messages, mode `frames`) | 1.50 MB | 750 kB | 25x |" in text
    assert "| events removed by foveation | 98.0% | ~98% (real scenes) |" in text
    # PNG / frames-per-second: 20 MB / 1 MB/s = 20 and 18 MB / 0.5 MB/s = 36 -> median 28
    assert "| one RGB image (PNG) / one second of binary frames (`every-window`) | 28x | ~20x |" in text
    # PNG / page: 2000 and 2250 -> median 2125
    assert "| one RGB image (PNG) / stitched page (`every-window`) | 2,125x | ~2400x |" in text
    assert "on-change" not in text  # no second mode: no rows for it


def test_report_on_a_two_recording_suite(tmp_path: Path) -> None:
    info = ReportInfo(date="2026-01-02 03:04 UTC", commit="abc1234567", backend="local", model="m.onnx (sha256 x)",
                      suite="2 fake recordings")
    path = write_report(typed(fake_results()), tmp_path, info)
    md = path.read_text()
    assert path.name == "README.md"
    for expected in ("2026-01-02 03:04 UTC", "`abc1234567`", "2 fake recordings", "![CER vs lux](cer_vs_lux.png)",
                     "Roboto (held out of training)", "| 000_bright | 1000 | still | pangram |", "## Bandwidth",
                     "darkread mean CER 4.0%", "RGB snapshot mean CER 50.0%", "## Failures", "001_dark: OCR engine tesseract: OcrError: boom"):
        assert expected in md, expected
    assert "| pangram | 2 | 4.0% | 10.0% |" in md  # engine comparison: tesseract's failure is left out of its mean
    assert "No 30-lux paragraph recordings" in md
    for name in ("cer_vs_lux.png", "cer_vs_lux_by_motion.png", "cer_vs_xheight.png", "ocr_backends_by_kind.png"):
        with Image.open(tmp_path / name) as image:
            assert image.format == "PNG" and image.size[0] > 300
    assert json.loads((tmp_path / "results.json").read_text())[1]["name"] == "001_dark"
    assert "## Where the errors come from" not in md  # no attribution.md beside it

    (tmp_path / "attribution.md").write_text("# Where the reading errors come from\n\n| lux | motion |\n|---:|---|\n")
    md = write_report(typed(fake_results()), tmp_path, info).read_text()
    assert "## Where the errors come from\n\n| lux | motion |" in md


def test_headline_compares_30_lux_paragraphs_with_the_paper() -> None:
    base = fake_results()[0]
    runs = [{**base, "name": f"p{k}", "lux": 30.0, "kind": "paragraph", "motion": motion,
             "darkread": {"cer": cer, "wer": 0.05}, "rgb": {"cer": 0.5, "wer": 0.9}}
            for k, (motion, cer) in enumerate([("still", 0.0), ("normal", 0.02), ("walking", 0.04)])]
    text = "\n".join(headline_table(typed(runs + fake_results())))
    assert "| still | 1 | 0.0% | 0.0% | 0.0% | 5.0% | 50.0% | 90.0% |" in text
    assert "| **all** | 3 | 2.0% | 2.0% | 4.0% | 5.0% | 50.0% | 90.0% |" in text
    assert "| still + normal | 2 | 1.0% | 1.0% | 2.0% | 5.0% | 50.0% | 90.0% |" in text
    assert "paragraphs: 2.0% over 3 recordings, at or below the paper's 2.5%" in text
    assert "normal head motion: 1.0% over 2 recordings, at or below" in text
    runs[0]["darkread"]["cer"] = 0.2
    assert "above the paper's" in "\n".join(headline_table(typed(runs)))


def test_cli_rebuilds_the_report_from_stored_results(tmp_path: Path) -> None:
    from darkread.cli import main

    suite = tmp_path / "suite"
    for result in fake_results():
        folder = suite / "eval_runs" / "every-window" / result["name"]  # results without "infer": every-window
        folder.mkdir(parents=True)
        (folder / "result.json").write_text(json.dumps(result))
    out = tmp_path / "report"
    assert main(["eval", "run", str(suite), "--report-only", "--infer", "every-window", "--out", str(out),
                 "--note", "a second run gave 3.0%"]) == 0
    md = (out / "README.md").read_text()
    assert "2 synthetic recordings" in md and "(cer_vs_lux.png)" in md
    assert "\n- a second run gave 3.0%\n" in md


def test_cli_reports_only_the_recordings_match_names(tmp_path: Path) -> None:
    from darkread.cli import main

    suite = tmp_path / "suite"
    for result in fake_results():
        folder = suite / "eval_runs" / "every-window" / result["name"]
        folder.mkdir(parents=True)
        (folder / "result.json").write_text(json.dumps(result))
    out = tmp_path / "report"
    assert main(["eval", "run", str(suite), "--report-only", "--infer", "every-window", "--out", str(out),
                 "--match", "*_dark"]) == 0
    names = [r["name"] for r in json.loads((out / "results.json").read_text())]
    assert names == ["001_dark"] and "1 synthetic recordings" in (out / "README.md").read_text()


def test_a_match_no_recording_has_is_one_clear_error(tmp_path: Path) -> None:
    from darkread.lab.eval.runner import evaluate_suite

    suite = tmp_path / "suite"
    (suite / "000_bright").mkdir(parents=True)
    (suite / "000_bright" / "text.txt").write_text("x")
    with pytest.raises(ValueError, match="no recording of .* has such a name"):
        evaluate_suite(suite, match=["*_lux10_*"], progress=False)


def test_cli_refuses_a_report_without_results(tmp_path: Path) -> None:
    from darkread.cli import main

    (tmp_path / "suite").mkdir()
    with pytest.raises(FileNotFoundError, match="no stored results"):
        main(["-vv", "eval", "run", str(tmp_path / "suite"), "--report-only", "--out", str(tmp_path / "out")])


def test_examples_grid_shows_the_rgb_crop_next_to_the_page(tmp_path: Path) -> None:
    from darkread.lab.eval.plots import plot_examples

    results = fake_results()
    for r in results:
        crop, page = tmp_path / f"{r['name']}_crop.png", tmp_path / f"{r['name']}_page.png"
        Image.new("RGB", (120, 60), (90, 90, 90)).save(crop)
        Image.new("L", (200, 80), 255).save(page)
        r["rgb"]["crop_png"], r["darkread"]["page_png"] = str(crop), str(page)
    path = plot_examples(typed(results), tmp_path / "examples.png")
    assert path is not None
    with Image.open(path) as image:
        assert image.size[1] > image.size[0] / 4  # two rows
    assert plot_examples(typed(fake_results()), tmp_path / "none.png") is None  # no images: no figure
    assert "(examples.png)" in write_report(typed(results), tmp_path / "report", ReportInfo()).read_text()


def test_engine_selection_skips_unconfigured_remote_engines(monkeypatch: pytest.MonkeyPatch) -> None:
    from darkread.lab.eval import runner

    monkeypatch.delenv("DARKREAD_OPENAI_API_KEY", raising=False)
    monkeypatch.delenv("DARKREAD_GOOGLE_API_KEY", raising=False)
    monkeypatch.delenv("DARKREAD_GOOGLE_BEARER_TOKEN", raising=False)
    monkeypatch.chdir(Path(__file__).parent)  # no .env here
    assert runner.available_backends([]) == []
    assert runner.available_backends(["openai", "google"]) == []


def test_grouping_by_two_conditions() -> None:
    rows = grouped_table(typed(fake_results()), ("lux", "motion"), "lux, motion", lambda v: f"{v[0]:g}, {v[1]}")
    assert [row.split(" | ")[0] for row in rows[2:]] == ["| 5, walking", "| 1000, still"]


def test_size_sweep_uses_one_condition_when_the_suite_has_one() -> None:
    from darkread.lab.eval.aggregate import sweep_subset

    base = fake_results()[0]
    sweep = [{**base, "name": f"s{x}", "xheight_px": float(x)} for x in (7, 9, 12)]
    other = {**fake_results()[1], "xheight_px": 8.0}
    subset, label = sweep_subset(typed([*sweep, other]), "xheight_px")
    assert [r.name for r in subset] == ["s7", "s9", "s12"]
    assert label == "1000 lux, still motion, pangram: 3 recordings"
    everything, label = sweep_subset(typed(fake_results()), "xheight_px")
    assert len(everything) == 2 and label == "all 2 recordings"


def test_report_names_the_commits_the_recordings_were_evaluated_at(tmp_path: Path) -> None:
    results = [{**r, "commit": "1111111111", "evaluated": f"2026-01-01 00:0{i} UTC"} for i, r in enumerate(fake_results())]
    md = write_report(typed(results), tmp_path, ReportInfo(commit="2222222222")).read_text()
    assert "- commit: `2222222222` (recordings evaluated at `1111111111`, 2026-01-01 00:00 UTC to 2026-01-01 00:01 UTC)" in md
    md = write_report(typed(results), tmp_path, ReportInfo(commit="1111111111")).read_text()
    assert "- commit: `1111111111`\n" in md


def test_real_scanpath_recordings_get_their_own_table_beside_the_model() -> None:
    from darkread.lab.eval.tables import scanpath_table

    docs = fake_results()
    for doc in docs:
        doc.update(kind="paragraph", lux=30.0, motion="still")
    human = {**docs[1], "name": "002_dark_human", "scanpath": "human", "darkread": {"cer": 0.03, "wer": 0.1}}
    results = typed([*docs, human])
    model = [r for r in results if r.scanpath == "model"]
    lines = scanpath_table(model, [r for r in results if r.scanpath == "human"])
    assert "| 30 | still | 1 | 3.0% | 3.0% | 2 | 4.0% |" in lines
    assert "No recordings" in scanpath_table(model, [])[0]


def on_change_results() -> list[dict[str, Any]]:
    """The same two recordings read by the edge in on-change mode: worse in the dark, a 10x smaller stream."""
    docs = fake_results()
    for doc, cer in zip(docs, (0.04, 0.16)):
        doc.update(infer="on-change")
        doc["darkread"] = {"text": "the quick fox", "cer": cer, "wer": 0.2}
        doc["bandwidth"]["frame_stream_bytes"] //= 10
        doc["bandwidth"]["page_bytes"] //= 2
    return docs


def test_modes_side_by_side_pair_recordings_and_show_the_difference() -> None:
    from darkread.lab.eval.aggregate import paired
    from darkread.lab.eval.tables import mode_headline, mode_table

    beside = typed(on_change_results())[:1]  # the other run covers one of the two recordings
    pairs = paired(typed(fake_results()), beside)
    assert [(p.name, p.infer, q.infer) for p, q in pairs] == [("000_bright", "every-window", "on-change")]
    rows = mode_table(pairs, ("lux", "motion"), "lux, motion", lambda v: f"{v[0]:g}, {v[1]}")
    assert rows[0] == "| lux, motion | n | `every-window` CER | `on-change` CER | `every-window` − `on-change` |"
    assert rows[2] == "| 1000, still | 1 | 2.0% | 4.0% | -2.0 pp |"
    assert rows[-1] == "| **all** | 1 | 2.0% | 4.0% | -2.0 pp |"

    runs = [{**fake_results()[0], "name": f"p{k}", "lux": 30.0, "kind": "paragraph", "motion": motion,
             "darkread": {"cer": cer}} for k, (motion, cer) in enumerate([("still", 0.0), ("normal", 0.02), ("walking", 0.1)])]
    views = [{**r, "infer": "on-change", "darkread": {"cer": r["darkread"]["cer"] + 0.01}} for r in runs]
    text = "\n".join(mode_headline(paired(typed(views), typed(runs))))
    assert "| 30-lux paragraphs | n | `on-change` CER | `every-window` CER | `on-change` − `every-window` |" in text
    assert "| still + normal | 2 | 2.0% | 1.0% | +1.0 pp |" in text
    assert "| walking | 1 | 11.0% | 10.0% | +1.0 pp |" in text
    assert "No 30-lux paragraph recordings evaluated in both modes." in mode_headline(pairs)


def test_bandwidth_table_gives_each_modes_stream() -> None:
    text = "\n".join(bandwidth_table(typed(fake_results()), typed(on_change_results())))
    assert "(2 in `every-window`, 2 in `on-change`)" in text
    # views: 150 kB per page (median of 200 and 100 kB), 75 kB/s; PNG 19 MB / 75 kB/s = 253x
    assert ("| `on-change`: the view stream as sent (View messages: one fused view per fixation, mode `frames`) | "
            "150 kB | 75.0 kB | 253x |") in text
    # PNG / view-stream second: 20 MB / 100 kB/s = 200 and 18 MB / 50 kB/s = 360 -> median 280
    assert "| one RGB image (PNG) / one second of the view stream (`on-change`) | 280x | ~20x |" in text
    assert "| one RGB image (PNG) / one second of binary frames (`every-window`) | 28x | ~20x |" in text
    # half the page bytes: 4000 and 4500 -> median 4250
    assert "| one RGB image (PNG) / stitched page (`on-change`) | 4,250x | ~2400x |" in text


def test_cli_puts_the_other_mode_beside_the_default(tmp_path: Path) -> None:
    """--infer both --report-only: the edge's default mode first, the other one beside it, from stored results."""
    from darkread.cli import main
    from darkread.edge.config import PipelineConfig

    suite = tmp_path / "suite"
    for mode, docs in (("every-window", fake_results()), ("on-change", on_change_results())):
        for result in docs:
            folder = suite / "eval_runs" / mode / result["name"]
            folder.mkdir(parents=True)
            (folder / "result.json").write_text(json.dumps(result))
    out = tmp_path / "report"
    assert main(["eval", "run", str(suite), "--infer", "both", "--report-only", "--out", str(out)]) == 0
    md = (out / "README.md").read_text()
    first = PipelineConfig().infer
    second = "on-change" if first == "every-window" else "every-window"
    assert f"- edge mode: `{first}` (`{second}` beside it: 2 recordings)" in md
    assert "## Edge modes side by side" in md and "![CER vs lux, both modes](cer_vs_lux_modes.png)" in md
    assert f"| lux | n | `{first}` CER | `{second}` CER | `{first}` − `{second}` |" in md
    sign = "-" if first == "every-window" else "+"
    assert f"| 5 | 1 | {'6.0%' if first == 'every-window' else '16.0%'} | " in md and f"| {sign}10.0 pp |" in md
    assert "one second of the view stream (`on-change`)" in md and "one second of binary frames (`every-window`)" in md
    with Image.open(out / "cer_vs_lux_modes.png") as image:
        assert image.format == "PNG" and image.size[0] > 300
    assert json.loads((out / f"results_{second}.json").read_text())[0]["name"] == "000_bright"

    # --beside a folder of the same mode is refused with one line
    with pytest.raises(ValueError, match="expected on-change results, found every-window"):
        main(["-vv", "eval", "run", str(suite), "--infer", "every-window", "--report-only", "--out", str(out),
              "--beside", str(suite / "eval_runs" / "every-window")])


def test_the_stored_results_name_paths_relative_to_the_suite(tmp_path: Path) -> None:
    from darkread.lab.eval.report import relative_paths

    suite = tmp_path / "suite"
    raw = {"name": "000", "darkread": {"page_png": str(suite / "eval_runs" / "on-change" / "000" / "read" / "page.png"),
                                        "text": "a/b"},
           "bandwidth": {"recording": str(suite / "000")}, "rgb": {"crop_png": str(tmp_path / "elsewhere" / "c.png")},
           "lines": ["/", 3]}
    portable = relative_paths(raw, suite)
    assert portable["darkread"] == {"page_png": "eval_runs/on-change/000/read/page.png", "text": "a/b"}
    assert portable["bandwidth"]["recording"] == "000"
    assert portable["rgb"]["crop_png"] == "../elsewhere/c.png"
    assert portable["lines"] == ["/", 3] and portable["name"] == "000"


def test_write_report_keeps_texts_and_takes_the_suite_out_of_paths_and_errors(tmp_path: Path) -> None:
    suite = tmp_path / "suite"
    run = suite / "eval_runs" / "every-window" / "000_bright"
    docs = fake_results()
    docs[0]["darkread"] = {**docs[0]["darkread"], "text": "/ a slash first", "page_png": str(run / "read" / "page.png")}
    docs[0]["rgb"] = {**docs[0]["rgb"], "crop_png": str(run / "rgb_crop.png")}
    docs[1]["darkread"] = {"error": f"FileNotFoundError: {suite / '001_dark'}/events.raw: no such file"}
    info = ReportInfo(date="2026-01-02 03:04 UTC", commit="abc1234567", backend="local", model="m", suite="2")
    write_report(typed(docs), tmp_path / "report", info, suite_dir=suite)
    stored = json.loads((tmp_path / "report" / "results.json").read_text())
    assert stored[0]["darkread"]["text"] == "/ a slash first"  # a read is never taken for a path
    assert stored[0]["darkread"]["page_png"] == "eval_runs/every-window/000_bright/read/page.png"
    assert stored[0]["rgb"]["crop_png"] == "eval_runs/every-window/000_bright/rgb_crop.png"
    assert stored[1]["darkread"]["error"] == "FileNotFoundError: 001_dark/events.raw: no such file"
    assert str(tmp_path) not in (tmp_path / "report" / "results.json").read_text()
    from darkread.lab.eval.report import relative_paths

    assert relative_paths(stored, suite) == stored  # results written so already stay as they are


def test_a_stored_result_stands_only_for_the_same_mode_and_network() -> None:
    """A model change re-reads the suite: a result read with other weights, or with none recorded, is not reused."""
    from darkread.lab.eval.results import why_evaluate_again

    doc = {"infer": "on-change", "model": "19999b3b014b"}
    assert why_evaluate_again(doc, "on-change", "19999b3b014b") is None
    assert "on-change result" in why_evaluate_again(doc, "every-window", "19999b3b014b")
    assert "4be7499df172" in why_evaluate_again({"infer": "on-change", "model": "4be7499df172"}, "on-change", "19999b3b014b")
    assert "not recorded" in why_evaluate_again({"infer": "on-change"}, "on-change", "19999b3b014b")


def test_before_and_after_names_the_commits_each_side_was_read_by() -> None:
    """The same recordings read by two commits: what differs is the code between them, and the
    section says which (an edge change shows up here as much as a cloud one)."""
    from darkread.lab.eval.before_after import before_after_section

    now = [{**r, "commit": "bbbbbbbbbb", "scanpath": "model"} for r in fake_results()]
    then = [{**r, "commit": "aaaaaaaaaa", "scanpath": "model",
             "darkread": {**r["darkread"], "cer": r["darkread"]["cer"] + 0.1}} for r in fake_results()]
    text = "\n".join(before_after_section(typed(now), typed(then), "docs/eval/before/results.json"))
    assert "(before `aaaaaaaaaa`, after `bbbbbbbbbb`)" in text
    assert "| 5 | 1 | 16.0% | 6.0% |" in text and "| **all** | 2 | 14.0% | 4.0% |" in text
