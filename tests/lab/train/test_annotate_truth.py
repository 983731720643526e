"""`train annotate --truth`: a synthetic reading recording's windows labelled from the simulator's own truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from darkread.lab.truth import annotate_from_truth, truth_windows
from darkread.models.train.annotate import SHARD_NAME, SUMMARY_NAME, AnnotationError
from darkread.models.train.data import load_dataset


@pytest.fixture(scope="module")
def walking_page(tmp_path_factory) -> Path:
    from darkread.models.synth.recording import RecordingSpec, write_recording

    spec = RecordingSpec(lux=10.0, motion="walking", kind="words", seconds=0.5, seed=12, xheight_px=10.0, n_lines=3,
                         line_chars=22)
    rec = tmp_path_factory.mktemp("truth") / "walking"
    write_recording(rec, spec, progress=False)
    return rec


def test_the_shard_holds_the_deblurred_windows_and_the_simulators_ink(tmp_path, walking_page) -> None:
    summary = annotate_from_truth(walking_page, tmp_path / "ann", every_ms=20.0)
    data = load_dataset(tmp_path / "ann")
    expected = truth_windows(walking_page, every_ms=20.0, deblur=True, denoise=True)
    assert expected.targets is not None and len(data.targets) == len(expected.targets) == summary["windows"] >= 10
    assert np.array_equal(data.targets, expected.targets)  # the simulator's ink, exactly
    np.testing.assert_allclose(data.voxels, expected.voxels, atol=2e-3)  # (stored as float16)
    assert set(data.meta["lux"].tolist()) == {10.0} and summary["motion"] == "walking" and summary["deblurred"]
    assert 0.0 < summary["ink_share"] < 0.5
    # walking at 10 lux smears a window over pixels: some windows are moved, so deblurring is not a no-op
    plain = truth_windows(walking_page, every_ms=20.0, deblur=False)
    assert any(not np.array_equal(a, b) for a, b in zip(plain.voxels, expected.voxels))
    assert json.loads((tmp_path / "ann" / SUMMARY_NAME).read_text())["annotated"] == summary["windows"]


def test_a_recording_without_truth_is_refused_in_one_line(tmp_path, walking_page) -> None:
    import shutil

    rec = tmp_path / "no_truth"
    shutil.copytree(walking_page, rec)
    (rec / "pose_truth.npz").unlink()
    with pytest.raises(AnnotationError, match=r"no simulator truth .* --truth$"):
        annotate_from_truth(rec, tmp_path / "out")
    assert not (tmp_path / "out" / SHARD_NAME).exists()


def test_a_recording_too_short_for_a_window_says_so_not_that_truth_is_missing(tmp_path, walking_page) -> None:
    import shutil

    rec = tmp_path / "cut"
    shutil.copytree(walking_page, rec)
    raw = (rec / "events.raw").read_bytes()
    (rec / "events.raw").write_bytes(raw[: len(raw) // 50])  # a few ms of events: no window is cut
    with pytest.raises(AnnotationError, match=r"no windows to annotate"):
        annotate_from_truth(rec, tmp_path / "out")


def test_the_cli_annotates_from_truth(tmp_path, walking_page) -> None:
    from tests.darkread_cli import darkread

    done = darkread("train", "annotate", str(walking_page), "--out", str(tmp_path / "cli"), "--truth", "--every-ms", "40")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["source"] == "simulator's true pose"
    assert (tmp_path / "cli" / SHARD_NAME).is_file()
