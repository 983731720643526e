"""End to end through the real command: print a target, synthesise a short recording of a marker page
in the shifted sensor regime, annotate it, and check the targets against the simulator's pose."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from darkread_cli import assert_one_error_line, darkread

from darkread.models.synth.marker_page import MarkerPageSpec, lay_out, load_layout, save_layout
from darkread.models.train.data import load_shard
from darkread.models.train.windows import read_events, window_stack

pytestmark = pytest.mark.slow  # a 0.6 s synthetic recording: ~20 s of simulation on a shared 2-core machine


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("marker") / "rec"
    result = darkread("synth", "recording", str(out), "--markers", "--regime", "shifted", "--lux", "100", "--seconds", "0.6",
                      "--seed", "7", "--xheight", "8", "--lines", "2", "--line-chars", "22", "--motion", "normal")
    assert result.returncode == 0, result.stderr[-2000:]
    return out


def test_marker_recording_is_annotated_within_a_pixel(recording, tmp_path):
    meta = json.loads((recording / "meta.json").read_text())
    assert meta["sensor_regime"] == "shifted" and meta["font"] == "DejaVu Sans Mono"
    assert meta["sensor"]["c_on"] > 0.3  # outside training's 0.18-0.32
    assert (recording / "page.layout.json").is_file() and (recording / "pose_truth.npz").is_file()
    load_layout(recording / "page.layout.json")

    result = darkread("train", "annotate", str(recording), "--out", str(tmp_path / "ann"), "--every-ms", "20", "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary == {k: v for k, v in json.loads((tmp_path / "ann" / "annotation.json").read_text()).items() if k != "config"}
    assert summary["windows"] >= 10
    assert summary["annotated_share"] >= 0.6
    assert summary["images_with_marker_pose"] >= 1
    assert summary["residual_px"]["median"] <= 1.2  # against the simulator's true pose
    assert abs(summary["time_offset_ms"]) <= 8.0

    shard = load_shard(tmp_path / "ann" / "shard-00000.npz")
    assert len(shard) == summary["annotated"]
    assert shard.voxels.shape[1:] == (4, 100, 200) and shard.targets.shape[1:] == (100, 200)
    ink = shard.targets.reshape(len(shard), -1).mean(axis=1)
    assert np.median(ink) > 0.02  # the windows sit on text
    assert np.all(np.diff(shard.meta["t_end_us"]) > 0)

    # the windows are cut as the edge cuts them (deblurred, denoised in dim light): tuned on what it will be given
    config = json.loads((tmp_path / "ann" / "annotation.json").read_text())["config"]
    assert config["deblur"] and config["denoise"]
    rec, events, sensor = read_events(recording)
    as_on_edge = window_stack(rec, events, sensor, every_ms=20, deblur=True, denoise=True)
    by_time = dict(zip(as_on_edge.t_end_us.tolist(), as_on_edge.voxels))
    for t_end, voxels in zip(shard.meta["t_end_us"].tolist(), shard.voxels):
        np.testing.assert_allclose(voxels, by_time[t_end], atol=1e-3)


def test_missing_layout_and_a_page_without_those_markers_fail_in_one_line(recording, tmp_path):
    copy = tmp_path / "rec"
    shutil.copytree(recording, copy)
    (copy / "page.layout.json").unlink()
    assert_one_error_line(darkread("train", "annotate", str(copy), "--out", str(tmp_path / "a")), "page layout not found")
    # a layout whose markers come from another dictionary: none of them is in the events
    other = lay_out(MarkerPageSpec(lines=("another page",), dictionary="DICT_6X6_50"))
    save_layout(copy / "other.layout.json", other)
    assert_one_error_line(darkread("train", "annotate", str(copy), "--layout", str(copy / "other.layout.json"),
                                   "--out", str(tmp_path / "b"), "--quiet"), "no markers")
    assert_one_error_line(darkread("train", "annotate", str(tmp_path / "nowhere"), "--out", str(tmp_path / "c")),
                          "no such recording")


def test_target_command_writes_page_and_layout(tmp_path):
    text = tmp_path / "text.txt"
    text.write_text("A short text to print\nwith markers around it.\n")
    result = darkread("train", "target", "--text", str(text), "--out", str(tmp_path / "page.pdf"))
    assert result.returncode == 0, result.stderr
    assert "actual size" in result.stdout
    assert (tmp_path / "page.pdf").read_bytes().startswith(b"%PDF")
    page = load_layout(tmp_path / "page.layout.json")
    assert page.spec.lines == ("A short text to print", "with markers around it.")
    assert_one_error_line(darkread("train", "target", "--text", str(tmp_path / "none.txt"), "--out", str(tmp_path / "p.pdf")),
                          "no such file")
