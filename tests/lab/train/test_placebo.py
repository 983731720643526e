"""Placebo networks: the base's weights slightly perturbed, read by the edge as the base is; the CLI's bad inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from darkread_cli import assert_one_error_line, darkread

from darkread.lab.train.placebo import perturbed, write_placebo
from darkread.models.train.calibrate import store_ink_temperature, stored_ink_temperature


@pytest.fixture(scope="module")
def base_model(tmp_path_factory) -> Path:
    """A BinaryUNet with random weights as ONNX, carrying an ink temperature."""
    import torch

    from darkread.models.train.export import export_onnx
    from darkread.models.train.net import BinaryUNet

    torch.manual_seed(0)
    path = export_onnx(BinaryUNet().eval(), tmp_path_factory.mktemp("base") / "base.onnx")
    return store_ink_temperature(path, 1.0)


def logits(path: Path, x: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(None, {session.get_inputs()[0].name: x})[0]


def test_perturbed_moves_every_weight_by_about_scale_relative() -> None:
    w = np.full((64, 64), 2.0, np.float32)
    p = perturbed(w, np.random.default_rng(0), 0.01)
    assert p.dtype == np.float32 and p.shape == w.shape
    relative = p / w - 1
    assert 0.008 < relative.std() < 0.012 and abs(relative.mean()) < 0.002


def test_a_placebo_answers_almost_as_its_base_and_keeps_its_temperature(tmp_path, base_model) -> None:
    placebo = write_placebo(base_model, tmp_path / "p.onnx", seed=3, scale=0.005)
    again = write_placebo(base_model, tmp_path / "again.onnx", seed=3, scale=0.005)
    other = write_placebo(base_model, tmp_path / "other.onnx", seed=4, scale=0.005)
    assert stored_ink_temperature(placebo) == 1.0
    x = np.random.default_rng(1).standard_normal((2, 4, 100, 200)).astype(np.float32)
    base, mine = logits(base_model, x), logits(placebo, x)
    assert not np.array_equal(base, mine)  # something changed...
    agree = np.mean((base > 0) == (mine > 0))
    assert agree > 0.98, agree  # ...but almost no pixel's answer
    np.testing.assert_array_equal(mine, logits(again, x))  # same seed, same placebo
    assert not np.array_equal(mine, logits(other, x))


def test_cli_placebo_writes_numbered_copies_and_bad_inputs_fail_in_one_line(tmp_path, base_model) -> None:
    done = darkread("train", "placebo", "--base", str(base_model), "--out", str(tmp_path / "p.onnx"), "--count", "2")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "p0.onnx").is_file() and (tmp_path / "p1.onnx").is_file()
    assert_one_error_line(darkread("train", "placebo", "--base", str(tmp_path / "none.onnx"), "--out", str(tmp_path / "x.onnx")),
                          "no such model file")
    assert_one_error_line(darkread("train", "placebo", "--base", str(base_model), "--out", str(tmp_path / "x.onnx"),
                                   "--scale", "2"), "--scale")
    truncated = tmp_path / "truncated.onnx"
    truncated.write_bytes(base_model.read_bytes()[:3000])
    assert_one_error_line(darkread("train", "placebo", "--base", str(truncated), "--out", str(tmp_path / "x.onnx")),
                          "truncated.onnx: not an ONNX model")
    assert_one_error_line(darkread("train", "placebo", "--base", str(base_model), "--out", str(tmp_path / "x.onnx"),
                                   "--count", "0"), "--count")


def test_cli_compare_reads_placebos_beside_the_tuned_model(tmp_path, base_model, shard_writer) -> None:
    from darkread.lab.train.placebo import write_placebo

    data = tmp_path / "val"
    data.mkdir()
    shard_writer(data / "shard-00000.npz", 4, 0)
    tuned = write_placebo(base_model, tmp_path / "tuned.onnx", seed=99, scale=0.05)  # any other network
    out = tmp_path / "cmp"
    done = darkread("train", "compare", str(data), "--base", str(base_model), "--model", str(tuned), "--out", str(out),
                    "--no-read", "--placebos", "2", "--quiet")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "ink F1 2 placebos" in done.stdout and (out / "placebos" / "placebo2.onnx").is_file()
    first = (out / "placebos" / "placebo1.onnx").read_bytes()
    assert first == write_placebo(base_model, tmp_path / "again.onnx", seed=1).read_bytes()  # seeds 1..N, as `train placebo`
    assert_one_error_line(darkread("train", "compare", str(data), "--base", str(base_model), "--model", str(tuned),
                                   "--out", str(out), "--placebos", "-1"), "--placebos")
    assert_one_error_line(darkread("train", "compare", str(data), "--base", str(base_model), "--model", str(tuned),
                                   "--out", str(out), "--placebos", "2", "--name", "placebo2"), "--name placebo2")
