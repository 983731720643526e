"""Rehearsal windows: simulated standard-regime reading, labelled from the truth, one shard directory finetune takes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from darkread_cli import assert_one_error_line, darkread

from darkread.lab.train.rehearsal import make_rehearsal, rehearsal_specs
from darkread.models.train.finetune import synthetic_windows


def test_sessions_cover_lux_and_motion_in_the_standard_regime() -> None:
    specs = rehearsal_specs(18, seed=601)
    assert [s.seed for s in specs] == list(range(601, 619))
    assert {(s.lux, s.motion) for s in specs} == {(lux, m) for lux in (5, 10, 20, 30, 50) for m in ("still", "normal", "walking")}
    assert all(s.regime == "standard" and s.split == "train" and s.n_lines == 3 and s.line_chars == 30 for s in specs)
    assert [s.lux for s in rehearsal_specs(4, seed=0)] == [5.0, 5.0, 5.0, 10.0]
    with pytest.raises(ValueError, match="--recordings 0"):
        rehearsal_specs(0, seed=1)


def test_grounded_sessions_cover_lux_motion_and_both_bias_profiles_with_k_drawn() -> None:
    specs = rehearsal_specs(36, seed=700, regime="grounded")
    assert {(s.lux, s.motion, s.bias_profile) for s in specs} == {
        (lux, m, b) for lux in (3, 5, 7, 10, 15, 30) for m in ("still", "normal", "walking") for b in ("factory", "dark")}
    assert all(s.regime == "grounded" and s.motion_regime == "grounded" and s.k_hz_per_chip_lux is None for s in specs)
    assert [s.bias_profile for s in specs[:2]] == ["factory", "dark"]  # the same scene's neighbours differ in biases
    with pytest.raises(ValueError, match="--regime shifted"):
        rehearsal_specs(2, seed=1, regime="shifted")


def test_a_rehearsal_set_is_a_shard_directory_that_resumes_and_guards_its_settings(tmp_path) -> None:
    out = tmp_path / "rehearsal"
    summary = make_rehearsal(out, count=1, seed=7, every_ms=40.0, seconds=0.5, progress=False)
    shard = out / "shard-00000.npz"
    with np.load(shard) as data:
        n = len(data["targets"])
        assert n >= 3 and data["voxels"].shape[1:] == (4, 100, 200) and data["targets"].any()  # the gaze is on the text
    assert summary["windows"] == n and summary["sessions"][0]["lux"] == 5.0 and not (out / ".work").exists()
    assert len(synthetic_windows(1000, [out], progress=False)) == n  # what `finetune --synthetic-dir` loads
    stamp = shard.stat().st_mtime_ns
    again = make_rehearsal(out, count=1, seed=7, every_ms=40.0, seconds=0.5, progress=False)
    assert shard.stat().st_mtime_ns == stamp and again["windows"] == n  # nothing made twice
    interrupted = {**json.loads((out / "rehearsal.json").read_text()), "sessions": []}  # stopped before the summary
    (out / "rehearsal.json").write_text(json.dumps(interrupted))
    resumed = make_rehearsal(out, count=1, seed=7, every_ms=40.0, seconds=0.5, progress=False)
    assert shard.stat().st_mtime_ns == stamp and resumed["windows"] == n  # counted from the shard it left
    with pytest.raises(ValueError, match="other settings"):
        make_rehearsal(out, count=1, seed=8, every_ms=40.0, seconds=0.5, progress=False)
    assert json.loads((out / "rehearsal.json").read_text())["first_seed"] == 7  # the refused run changed nothing


def test_cli_rehearsal_bad_inputs_fail_in_one_line(tmp_path) -> None:
    for flag, value in (("--recordings", "0"), ("--every-ms", "-5")):  # argparse's usage error: exit 2, the flag named
        done = darkread("train", "rehearsal", str(tmp_path / "r"), flag, value)
        assert done.returncode == 2 and f"argument {flag}: must be" in done.stderr and "Traceback" not in done.stderr
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "rehearsal.json").write_text(json.dumps({"count": 3, "first_seed": 1, "every_ms": 10.0, "spec": {}}))
    assert_one_error_line(darkread("train", "rehearsal", str(tmp_path / "r"), "--quiet"), "other settings")
