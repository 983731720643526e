"""Opening recordings: directories in the recording format and bare .raw files."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from darkread.edge.errors import RecordingError
from darkread.edge.io.calibration import Calibration, save_calibration
from darkread.edge.io.gaze_csv import write_gaze_csv
from darkread.edge.io.recording import open_recording


def make_recording(root: Path, *, text: bool = True) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "events.raw").write_bytes(b"% format EVT3;height=720;width=1280\n% end\n")
    t = np.arange(5, dtype=np.int64) * 16_667
    write_gaze_csv(root / "general_eye_gaze.csv", t, np.zeros(5), np.zeros(5), np.zeros(5), np.full(5, 0.45))
    save_calibration(
        root / "calibration.json",
        Calibration(1280, 720, 1400.0, 1400.0, 640.0, 360.0, (0.0, 0.0, 0.0, 0.0), np.eye(4), 42),
    )
    if text:
        (root / "text.txt").write_text("hello\nworld")
    (root / "meta.json").write_text('{"lux": 5.0}')
    return root


def test_opens_a_directory(tmp_path: Path) -> None:
    rec = open_recording(make_recording(tmp_path / "rec"))
    assert rec.raw_path == tmp_path / "rec" / "events.raw"
    assert rec.text == "hello\nworld" and rec.meta == {"lux": 5.0} and rec.rgb_path is None
    assert rec.calibration.gaze_to_event_time_offset_us == 42
    assert len(rec.gaze()) == 5 and rec.gaze() is rec.gaze()


def test_text_is_optional(tmp_path: Path) -> None:
    assert open_recording(make_recording(tmp_path / "rec", text=False)).text is None


def test_missing_files_are_all_named(tmp_path: Path) -> None:
    root = make_recording(tmp_path / "rec")
    (root / "events.raw").unlink()
    (root / "calibration.json").unlink()
    with pytest.raises(RecordingError) as info:
        open_recording(root)
    assert "events.raw" in str(info.value) and "calibration.json" in str(info.value)
    assert "general_eye_gaze.csv" not in str(info.value)


def test_bare_raw_needs_explicit_gaze_and_calibration(tmp_path: Path) -> None:
    root = make_recording(tmp_path / "rec")
    raw = shutil.copy(root / "events.raw", tmp_path / "other.raw")
    with pytest.raises(RecordingError, match="--gaze") as info:
        open_recording(raw)
    assert "--calibration" in str(info.value)
    rec = open_recording(raw, gaze=str(root / "general_eye_gaze.csv"), calibration=str(root / "calibration.json"))
    assert rec.raw_path == Path(raw) and rec.text is None and rec.meta == {}


def test_nonexistent_path(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such recording"):
        open_recording(tmp_path / "nope")


@pytest.mark.shared
def test_sample_recording(shared_sample_recording: Path) -> None:
    rec = open_recording(shared_sample_recording)
    assert rec.meta["event_count"] == 488780
    assert rec.text is not None and rec.text.count("\n") == rec.meta["n_lines"] - 1
    assert rec.rgb_path is not None and rec.rgb_path.name == "rgb.png"
    assert (rec.calibration.width, rec.calibration.height) == (1280, 720)
    assert len(rec.gaze()) == 211


@pytest.mark.shared
def test_recording_reader_streams_the_events(shared_sample_recording: Path) -> None:
    pytest.importorskip("darkread.edge.io.raw")
    rec = open_recording(shared_sample_recording)
    reader = rec.reader(chunk_bytes=1 << 20)
    assert (reader.header.width, reader.header.height) == (1280, 720)
    assert sum(len(chunk) for chunk in reader) == rec.meta["event_count"]
