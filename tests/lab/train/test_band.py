"""The tune across the sensor's band: its window sets made once and kept, the tuned network exported and readable."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from darkread_cli import assert_one_error_line, darkread

from darkread.edge.reconstruct import Reconstructor
from darkread.lab.train.band import BAND_RECIPE, band_sets, tune_across_band
from darkread.models import MODELS_DIR

pytest.importorskip("torch")


def test_a_small_band_tune_makes_its_sets_once_and_exports_a_network_the_edge_reads(tmp_path) -> None:
    recipe = replace(BAND_RECIPE, grounded_sessions=1, standard_sessions=1, session_s=0.5, crops=100, steps=3, minutes=5.0)
    out = tmp_path / "band.onnx"
    info = tune_across_band(MODELS_DIR / "binary_unet.onnx", tmp_path / "work", out, recipe=recipe, progress=False)
    sets = band_sets(tmp_path / "work")
    grounded = json.loads((sets["grounded"] / "rehearsal.json").read_text())
    assert grounded["spec"]["regime"] == "grounded" and grounded["sessions"][0]["biases"] == "factory"
    assert info["tune"]["steps"] == 3 and info["tune"]["annotated_windows"] == grounded["windows"] > 0
    assert json.loads((tmp_path / "work" / "band.json").read_text())["recipe"]["train_only"] == ["stem", "down1", "down2"]
    net = Reconstructor(out, warmup=0)
    assert net.temperature == 1.5 and net(np.zeros((4, 100, 200), np.float32)).shape == (100, 200)  # the shipped T carried
    stamps = {name: (path / "shard-00000.npz").stat().st_mtime_ns for name, path in sets.items()}
    tune_across_band(MODELS_DIR / "binary_unet.onnx", tmp_path / "work", out, recipe=recipe, progress=False)
    assert {name: (path / "shard-00000.npz").stat().st_mtime_ns for name, path in sets.items()} == stamps  # nothing made twice


def test_cli_band_without_its_base_network_is_one_line(tmp_path) -> None:
    assert_one_error_line(darkread("train", "band", "--base", str(tmp_path / "none.onnx"), "--work", str(tmp_path)),
                          "no such model file")
