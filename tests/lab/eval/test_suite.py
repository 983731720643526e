from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from darkread.lab.eval.suite import (
    FONTS,
    HELD_OUT_FONTS,
    LUX_LEVELS,
    MOTIONS,
    TEXT_KINDS,
    XHEIGHTS_PX,
    load_suite,
    make_suite,
    select_entries,
    spec_document,
    suite_entries,
)
from darkread.models.synth.fonts import HELD_OUT_FAMILIES, TRAIN_FAMILIES


@pytest.mark.parametrize("small", [True, False])
def test_suite_covers_every_axis_with_fixed_unique_seeds(small: bool) -> None:
    entries = suite_entries(small=small)
    assert entries == suite_entries(small=small)  # same every time
    assert len({e.seed for e in entries}) == len(entries) and len({e.name for e in entries}) == len(entries)
    assert {e.lux for e in entries} == set(LUX_LEVELS)
    assert {e.kind for e in entries} == set(TEXT_KINDS)
    assert {e.motion for e in entries} == set(MOTIONS)
    assert {e.font for e in entries} == set(FONTS)
    assert all(7 <= e.xheight_px <= 12 for e in entries)
    if not small:
        assert {e.xheight_px for e in entries} == set(XHEIGHTS_PX)


def test_fonts_include_one_held_out_of_training() -> None:
    assert set(HELD_OUT_FONTS) <= set(HELD_OUT_FAMILIES)
    assert set(FONTS) - set(HELD_OUT_FONTS) <= set(TRAIN_FAMILIES)


def test_small_suite_is_ci_sized() -> None:
    entries = suite_entries(small=True)
    assert 10 <= len(entries) <= 20
    assert all(e.read_once and e.split == "val" for e in entries)  # each ends once its page was read
    assert sum(e.n_lines * e.line_chars for e in entries) <= 20 * 60  # ~20 characters read per second


def test_entry_spec_fixes_everything_the_generator_would_draw() -> None:
    spec = suite_entries(small=True)[0].recording_spec()
    assert None not in (spec.font, spec.xheight_px, spec.n_lines, spec.line_chars)


def test_load_suite_lists_recordings_and_explains_an_empty_folder(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="make-suite"):
        load_suite(tmp_path)
    for name in ("b", "a"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "text.txt").write_text("x")
    (tmp_path / "eval_runs").mkdir()
    assert [p.name for p in load_suite(tmp_path)] == ["a", "b"]


@pytest.mark.slow
def test_make_suite_then_evaluate_one_recording_end_to_end(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A one-second suite recording through make_suite, darkread (edge -> cloud -> OCR), the RGB baseline
    and the bandwidth accounting. Checks the plumbing, not the model's quality."""
    import darkread.lab.eval.suite as suite_module
    from darkread.lab.eval.runner import evaluate_recording

    short = replace(suite_entries(small=True)[0], seconds=1.0, n_lines=2, line_chars=12)
    monkeypatch.setattr(suite_module, "suite_entries", lambda small=False: [short])
    entries = make_suite(tmp_path, small=True, progress=False)
    folder = tmp_path / entries[0].name
    for name in ("events.raw", "general_eye_gaze.csv", "calibration.json", "text.txt", "meta.json", "spec.json"):
        assert (folder / name).is_file(), name
    doc = json.loads((tmp_path / "suite.json").read_text())
    assert doc["small"] is True and doc["recordings"][0]["seed"] == short.seed
    before = (folder / "events.raw").stat().st_mtime_ns
    make_suite(tmp_path, small=True, progress=False)  # complete recordings are kept
    assert (folder / "events.raw").stat().st_mtime_ns == before

    result = evaluate_recording(folder, tmp_path / "run", compare=["rapidocr"])
    assert result["lux"] == short.lux and result["kind"] == short.kind
    assert "error" not in result["rgb"], result["rgb"]  # the RGB baseline re-created the same page
    assert 0.0 <= result["rgb"]["cer"] and result["rgb"]["exposure_ms"] > 0
    assert "error" not in result["darkread"], result["darkread"]
    assert result["darkread"]["frames"] > 0 and result["darkread"]["cer"] is not None
    bw = result["bandwidth"]
    assert bw["frames_measured"] and bw["frame_stream_bytes"] == result["darkread"]["bytes_sent"]
    assert bw["rgb"]["raw"] == 2880 * 2880 * 3 and bw["page_bytes"] > 0
    assert 0 < bw["events_foveated"] < bw["events"]
    assert json.loads((tmp_path / "run" / "result.json").read_text())["name"] == folder.name

    # --no-rgb: darkread's reading alone (a second simulator's suite has the first one's scenes)
    alone = evaluate_recording(folder, tmp_path / "run_alone", rgb=False)
    assert alone["rgb"] is None and alone["bandwidth"] is None and alone["darkread"]["frames"] > 0
    # evaluated again in the same folder (--force): a fresh read, not a second session beside the first
    again = evaluate_recording(folder, tmp_path / "run_alone", rgb=False)
    from darkread.lab.eval.attribution import stored_frames

    assert len(stored_frames(tmp_path / "run_alone" / "read" / "cloud")) == again["darkread"]["frames"]

    # where its errors come from: the stored frames against the simulator's truth, read three ways
    from darkread.lab.eval.attribution import write_attribution

    work = tmp_path / "attribution_work"
    work.mkdir()
    (tmp_path / "run").rename(work / folder.name)
    report = write_attribution(tmp_path, work, tmp_path / "attribution.md", backend="rapidocr", progress=False)
    (row,) = json.loads(report.with_suffix(".json").read_text())
    assert row["name"] == folder.name and row["frames"] == result["darkread"]["frames"]
    assert row["cer_stitched"] == min(1.0, result["darkread"]["cer"])
    assert 0.0 <= row["cer_ideal"] <= 1.0 and 0.0 <= row["cer_placed"] <= 1.0
    assert 0.0 <= row["cer_true_motion"] <= 1.0  # read again end to end with the simulator's motion
    assert (work / folder.name / "true_motion" / "page.png").is_file()
    assert 0.0 < row["frame_recall"] <= 1.0 and 0.0 < row["frame_precision"] <= 1.0
    assert f"| {short.lux:g} | **all** | 1 |" in report.read_text()
    kept = (work / folder.name / "attribution.json").stat().st_mtime_ns  # a rerun reuses the stored figures
    assert write_attribution(tmp_path, work, tmp_path / "again.md", backend="rapidocr", progress=False).is_file()
    assert (work / folder.name / "attribution.json").stat().st_mtime_ns == kept
    assert json.loads((tmp_path / "again.json").read_text()) == [row]
    (work / folder.name / "attribution.json").write_text('{"backend": "rapidocr", "name": ')  # truncated: attributed again
    assert write_attribution(tmp_path, work, tmp_path / "again.md", backend="rapidocr", progress=False).is_file()
    assert json.loads((tmp_path / "again.json").read_text()) == [row]
    assert json.loads((work / folder.name / "attribution.json").read_text())["name"] == folder.name

    # the stored frames stitched and read again by the cloud code of now, placements against the truth
    from darkread.lab.eval.restitch import write_restitch

    restitched = write_restitch(tmp_path, work, tmp_path / "restitch.md", backend="rapidocr", progress=False)
    (again_row,) = json.loads(restitched.with_suffix(".json").read_text())
    assert again_row["frames"] == result["darkread"]["frames"] and again_row["cer_stored"] == row["cer_stitched"]
    assert 0.0 <= again_row["cer"] <= 1.0
    assert again_row["registration_px"] is not None and again_row["registration_px"] < 3.0 and again_row["misplaced"] == 0
    assert again_row["lines"] and all(0.0 <= cer <= 1.0 and chars > 0 for cer, chars, _ in again_row["lines"])
    beside = write_restitch(tmp_path, work, tmp_path / "beside.md", backend="rapidocr", before=restitched.with_suffix(".json"),
                            progress=False)
    assert "CER re-read before" in beside.read_text() and f"| {short.lux:g} | **all** | 1 |" in beside.read_text()


def test_cli_make_suite_form(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from darkread.cli import main

    assert main(["eval", "make-suite", str(tmp_path / "s"), "--small", "--limit", "0"]) == 0
    assert json.loads((tmp_path / "s" / "suite.json").read_text())["recordings"] == []
    assert "0 recordings" in capsys.readouterr().out
    with pytest.raises(SystemExit) as usage:  # the form's own usage names the missing folder
        main(["eval", "make-suite"])
    assert usage.value.code == 2 and "OUT" in capsys.readouterr().err


def test_real_scanpath_block_is_appended_and_old_specs_stay_complete() -> None:
    from darkread.lab.eval.suite import HUMAN_BLOCK, spec_document

    entries = suite_entries()
    human = [e for e in entries if e.scanpath == "human"]
    assert [(e.lux, e.motion) for e in human] == list(HUMAN_BLOCK)
    assert all(e.name.endswith("_human") and e.kind == "paragraph" for e in human)
    assert entries[: len(entries) - len(human)] == [e for e in entries if e.scanpath == "model"]  # appended
    assert "scanpath" not in spec_document(entries[0])  # a suite written before the block still matches
    assert spec_document(human[0])["scanpath"] == "human"


def test_make_suite_match_selects_recordings_by_name(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no recording"):
        make_suite(tmp_path, match="*nothing-like-this*", progress=False)


def test_simulator_check_is_the_suites_own_words_and_paragraphs_at_30_10_5_lux() -> None:
    from dataclasses import replace

    from darkread.lab.eval.suite import simulator_check_entries, spec_document

    check = simulator_check_entries()
    full = {e.name: e for e in suite_entries()}
    assert len(check) == 18 and all(full[e.name] == e for e in check)  # same names, seeds, texts, durations
    for lux in (30.0, 10.0, 5.0):
        level = [e for e in check if e.lux == lux]
        assert len(level) == 6 and {e.motion for e in level} == {"still", "normal", "walking"}
        assert {e.kind for e in level} == {"words", "paragraph"} and {e.scanpath for e in level} == {"model"}
    assert "simulator" not in spec_document(check[0])  # suites written before the option still match
    hesim = replace(check[0], simulator="hesim")
    assert spec_document(hesim)["simulator"] == "hesim" and hesim.recording_spec().simulator == "hesim"


def test_make_suite_refuses_an_unknown_simulator_or_subset(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--simulator 'esim'"):
        make_suite(tmp_path, simulator="esim", progress=False)
    with pytest.raises(ValueError, match="--subset 'most'"):
        make_suite(tmp_path, subset="most", progress=False)
    with pytest.raises(ValueError, match="leave out --small"):
        make_suite(tmp_path, subset="simulator-check", small=True, progress=False)


def test_a_recording_in_another_font_is_the_same_scene_named_after_both_fonts() -> None:
    from darkread.lab.eval.suite import in_font

    entry = next(e for e in suite_entries() if e.font == "Roboto")
    swapped = in_font(entry, "DejaVu Sans")
    assert swapped.font == "DejaVu Sans" and "roboto" not in swapped.name.removesuffix("_as_roboto")
    assert swapped.name.endswith("_as_roboto") and "_dejavusans_xh" in swapped.name
    assert swapped.name[:3] == entry.name[:3]
    assert (swapped.seed, swapped.lux, swapped.motion, swapped.kind, swapped.xheight_px) == (
        entry.seed, entry.lux, entry.motion, entry.kind, entry.xheight_px)


def test_make_suite_font_selects_what_it_swaps_and_refuses_an_unknown_family(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--font 'Comic Sans'"):
        make_suite(tmp_path, font="Comic Sans", progress=False)
    from darkread.lab.eval.suite import select_entries

    dim = select_entries(match="*_lux5_*")
    swapped = select_entries(match="*_lux5_*", font="Roboto")
    assert len(dim) == 12 and len(swapped) == 8  # the four already in Roboto are left out
    assert all(e.font == "Roboto" and e.name.endswith(("_as_dejavusans", "_as_stixgeneral")) for e in swapped)
    assert make_suite(tmp_path, match="*_lux5_*", font="Roboto", only=0, progress=False) == []  # (--limit 0: nothing written)
    suite = json.loads((tmp_path / "suite.json").read_text())
    assert suite["font"] == "Roboto"


def test_cli_make_suite_with_a_font(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from darkread.cli import main

    assert main(["eval", "make-suite", str(tmp_path / "s"), "--match", "*_lux5_*", "--font", "DejaVu Sans",
                 "--limit", "0"]) == 0
    assert "0 recordings" in capsys.readouterr().out


def test_a_suite_in_another_sensor_regime_is_the_same_scenes() -> None:
    from darkread.lab.eval.suite import select_entries, spec_document

    standard = select_entries(match="*_lux5_*")
    fast = select_entries(match="*_lux5_*", regime="fast-photoreceptor")
    assert [e.name for e in fast] == [e.name for e in standard] and all(e.regime == "fast-photoreceptor" for e in fast)
    assert spec_document(standard[0])["regime"] == "standard"  # what the suites written so far hold
    doc = spec_document(fast[0])
    assert doc["regime"] == "fast-photoreceptor" and {k: v for k, v in doc.items() if k != "regime"} == {
        k: v for k, v in spec_document(standard[0]).items() if k != "regime"}


def test_make_suite_refuses_an_unknown_regime_or_one_for_the_other_simulator(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--regime 'bright'"):
        make_suite(tmp_path, regime="bright", progress=False)
    with pytest.raises(ValueError, match="leave out --simulator hesim"):
        make_suite(tmp_path, regime="fast-photoreceptor", simulator="hesim", progress=False)


def test_make_suite_takes_a_motion_regime_for_every_recording(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--motion-regime 'wild'"):
        make_suite(tmp_path, motion_regime="wild", progress=False)
    entries = select_entries(small=True, motion_regime="strong")
    assert entries and all(e.motion_regime == "strong" and e.recording_spec().motion_regime == "strong" for e in entries)
    assert "motion_regime" not in spec_document(select_entries(small=True)[0])  # older suites' spec.json stay complete


def test_add_imu_on_a_folder_without_suite_recordings_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from darkread.cli import main

    assert main(["eval", "add-imu", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "spec.json" in err[0] and "make-suite" in err[0]


def test_make_suite_fixes_k_and_biases_for_the_grounded_sensor_only(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="add --regime grounded"):
        make_suite(tmp_path, biases="dark", progress=False)
    with pytest.raises(ValueError, match="add --regime grounded"):
        make_suite(tmp_path, k=130.0, progress=False)
    with pytest.raises(ValueError, match="--k 1: a photoreceptor K"):
        make_suite(tmp_path, regime="grounded", k=1.0, progress=False)
    with pytest.raises(ValueError, match="bias profile 'night'"):
        make_suite(tmp_path, regime="grounded", biases="night", progress=False)
    entry = select_entries(small=True, regime="grounded", biases="dark", k=40.0)[0]
    spec = entry.recording_spec()
    assert spec.bias_profile == "dark" and spec.k_hz_per_chip_lux == 40.0
    assert spec_document(entry)["k_hz_per_chip_lux"] == 40.0
    assert "k_hz_per_chip_lux" not in spec_document(select_entries(small=True)[0])  # older suites' spec.json stay complete


def test_a_fixed_k_changes_the_grounded_sensor_in_k_alone() -> None:
    import numpy as np

    from darkread.models.synth.session import SessionSpec, session_sensor

    drawn = session_sensor(SessionSpec(regime="grounded", lux=5.0), np.random.default_rng(7), 5.0)
    fixed = session_sensor(SessionSpec(regime="grounded", lux=5.0, k_hz_per_chip_lux=40.0), np.random.default_rng(7), 5.0)
    assert fixed.k_hz_per_chip_lux == 40.0 != drawn.k_hz_per_chip_lux
    assert {k: v for k, v in fixed.to_dict().items() if k != "k_hz_per_chip_lux"} == {
        k: v for k, v in drawn.to_dict().items() if k != "k_hz_per_chip_lux"}
    with pytest.raises(ValueError, match="fixed K or a standard law is the grounded"):
        session_sensor(SessionSpec(regime="standard", lux=5.0, k_hz_per_chip_lux=40.0), np.random.default_rng(7), 5.0)


def test_make_suite_k_names_the_band() -> None:
    from darkread.lab.eval.cli import k_of

    assert (k_of("slow"), k_of("central"), k_of("fast"), k_of("75")) == (40.0, 130.0, 400.0, 75.0)


def test_make_suite_puts_single_laws_back_to_the_standard_model() -> None:
    with pytest.raises(ValueError, match="--standard-law 'gravity'"):
        make_suite("/nonexistent-suite", regime="grounded", standard_laws=["gravity"], progress=False)
    with pytest.raises(ValueError, match="add --regime grounded"):
        make_suite("/nonexistent-suite", standard_laws=["noise"], progress=False)
    entry = select_entries(small=True, regime="grounded", standard_laws=["noise"])[0]
    assert spec_document(entry)["standard_laws"] == ["noise"]
    assert "standard_laws" not in spec_document(select_entries(small=True, regime="grounded")[0])
