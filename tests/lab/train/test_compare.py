"""`train compare` on a tiny case: two models on a shard directory, numbers checked against a direct count."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from darkread.lab.train.compare import compare
from darkread.models.train.data import load_dataset
from darkread.models.train.evaluate import predict_onnx
from darkread.models.train.export import export_onnx
from darkread.models.train.ink_scores import ink_scores
from darkread.models.train.net import BinaryUNet


@pytest.fixture(scope="module")
def two_models(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("models")
    out = {}
    for i, name in enumerate(("shipped", "tuned")):
        torch.manual_seed(i)
        model = BinaryUNet().eval()
        with torch.no_grad():
            model.head.bias.fill_(0.3 * (i - 0.5))  # one predicts more ink than the other
        out[name] = export_onnx(model, root / f"{name}.onnx")
    return out


def test_compare_scores_each_model_on_a_shard_directory(tmp_path, two_models, shard_writer) -> None:
    data = tmp_path / "val"
    data.mkdir()
    shard_writer(data / "shard-00000.npz", 6, 0)
    report = compare([data], two_models, tmp_path / "out", read=False, progress=False)
    truth = load_dataset(data)
    for name, path in two_models.items():
        expected = ink_scores(predict_onnx(path, truth.voxels), truth.targets)["f1"]
        assert report["rows"][0][name]["ink"]["f1"] == pytest.approx(expected, abs=1e-4)
        assert report["summary"][0][f"{name}_ink_f1"] == pytest.approx(expected, abs=1e-4)
    assert report["summary"][0]["windows"] == 6 and "read" not in report["rows"][0]["tuned"]
    saved = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert saved["models"]["tuned"]["sha256_12"] != saved["models"]["shipped"]["sha256_12"]
    table = (tmp_path / "out" / "compare.md").read_text()
    assert "| val | 1 | 6 |" in table and (tmp_path / "out" / "compare.png").stat().st_size > 1000


def test_a_plain_synthetic_page_is_scored_against_the_simulators_own_ink(tmp_path, two_models) -> None:
    """A recording without markers carries its truth too: every window's target is the simulator's ink mask."""
    from darkread.lab.truth import truth_windows
    from darkread.models.synth.recording import RecordingSpec, load_pose_truth, session_spec, write_recording
    from darkread.models.synth.scene import Region
    from darkread.models.synth.session import make_session

    spec = RecordingSpec(lux=100.0, motion="normal", kind="words", seconds=0.45, seed=11, xheight_px=10.0, n_lines=3,
                         line_chars=22, regime="shifted")
    rec = tmp_path / "plain"
    meta = write_recording(rec, spec, progress=False)
    assert meta["truth"] == {"pose": "pose_truth.npz", "ink": "page_ink.npz"} and not (rec / "page.layout.json").exists()
    scored = truth_windows(rec)
    assert scored.targets is not None and len(scored.targets) >= 5 and scored.source == "simulator's true pose"

    session = make_session(session_spec(spec), spec.seed)  # the same scene, re-made from its seed
    t0_us = load_pose_truth(rec).t_us[0]  # the event clock's start
    from darkread.models.train.windows import read_events, window_stack

    windows = window_stack(*read_events(rec), every_ms=40.0)
    inked = 0
    for target, (x0, y0), t_end in zip(scored.targets, windows.origins, windows.t_end_us):
        expected = session.scene.ink_mask(Region.of(session.calib, int(x0), int(y0), 200, 100), (t_end - t0_us) * 1e-6)
        assert np.mean(target == expected) > 0.999  # measured 0.99995-1 (half a texel off: 0.992-0.997)
        inked += int(expected.sum() > 100)
    assert inked >= 3  # the gaze is on the text: the windows hold ink

    report = compare([rec], two_models, tmp_path / "out", read=False, progress=False)
    row = report["rows"][0]
    assert row["truth"] == "simulator's true pose" and row["shipped"]["ink"]["windows"] == len(scored.targets)
    ink = (rec / "page_ink.npz").read_bytes()
    (rec / "page_ink.npz").write_bytes(ink[:300])  # a damaged truth file: one line that names it
    with pytest.raises(ValueError, match=r"page_ink.npz: not a readable simulator truth file"):
        truth_windows(rec)
    (rec / "page_ink.npz").unlink()
    assert truth_windows(rec).targets is None  # the pose alone is not a truth


def _row(name: str, cers: dict[str, float]) -> dict:
    return {"input": name, "kind": "recording", "lux": 10.0, "regime": "standard", "group": None,
            **{m: {"ink": {"tp": 8, "fp": 2, "fn": 2, "windows": 5, "f1": 0.8}, "read": {"cer": c}} for m, c in cers.items()}}


def test_placebos_give_the_chance_range_and_where_the_tuned_model_falls() -> None:
    from darkread.lab.train.compare import against_chance, markdown, summarise

    rows = [_row("a", {"shipped": 0.20, "tuned": 0.30, "placebo1": 0.21, "placebo2": 0.19}),
            _row("b", {"shipped": 0.10, "tuned": 0.12, "placebo1": 0.10, "placebo2": 0.13})]
    (entry,) = summarise(rows, ["shipped", "tuned"], ["placebo1", "placebo2"])
    assert entry["chance_cer"] == [pytest.approx(0.155), pytest.approx(0.16)]
    assert entry["tuned_cer"] == pytest.approx(0.21) and entry["tuned_cer_against_chance"] == "above"
    assert entry["cer_lower"] == 0 and entry["cer_higher"] == 2  # tuned against the base only, not the placebos
    assert [against_chance(v, [0.1, 0.2]) for v in (0.05, 0.1, 0.2, 0.25)] == ["below", "inside", "inside", "above"]
    report = {"models": {m: {"path": f"{m}.onnx", "sha256_12": m} for m in ("shipped", "tuned", "placebo1", "placebo2")},
              "chance": ["placebo1", "placebo2"], "backend": "local", "rows": rows, "summary": [entry]}
    table = markdown(report)
    assert "CER 2 placebos" in table and "15.5 % – 16.0 %" in table and "| above |" in table
    assert "placebo1.onnx" not in table  # the placebos are one column, not four
    assert "| a | 0.800 | 0.800 | 20.0 % | 30.0 % | 19.0 % – 21.0 % |" in table


def test_compare_with_placebos_on_a_shard_directory(tmp_path, two_models, shard_writer) -> None:
    from darkread.lab.train.placebo import write_placebo

    data = tmp_path / "val"
    data.mkdir()
    shard_writer(data / "shard-00000.npz", 6, 0)
    models = {**two_models, **{f"placebo{i}": write_placebo(two_models["shipped"], tmp_path / f"p{i}.onnx", seed=i) for i in (1, 2)}}
    report = compare([data], models, tmp_path / "out", read=False, chance=["placebo1", "placebo2"], progress=False)
    (entry,) = report["summary"]
    low, high = entry["chance_ink_f1"]
    assert low <= high and abs(low - entry["shipped_ink_f1"]) < 0.05  # a placebo reads almost as its base
    assert entry["tuned_ink_f1_against_chance"] in {"below", "inside", "above"}
    assert "ink F1 2 placebos" in (tmp_path / "out" / "compare.md").read_text()
    assert (tmp_path / "out" / "compare.png").stat().st_size > 1000


def test_compare_in_parallel_gives_the_same_rows_in_input_order(tmp_path, two_models, shard_writer) -> None:
    dirs = []
    for k, n in enumerate((3, 5, 4)):
        d = tmp_path / f"val{k}"
        d.mkdir()
        shard_writer(d / "shard-00000.npz", n, k)
        dirs.append(d)
    alone = compare(dirs, two_models, tmp_path / "one", read=False, progress=False)
    together = compare(dirs, two_models, tmp_path / "two", read=False, jobs=2, progress=False)
    assert [r["input"] for r in together["rows"]] == ["val0", "val1", "val2"]
    assert [r["tuned"]["ink"] for r in together["rows"]] == [r["tuned"]["ink"] for r in alone["rows"]]
    assert together["summary"] == alone["summary"]
