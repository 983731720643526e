"""The main job, end to end: ``darkread read`` on the shipped sample recording.

A real edge replays the recording into a real uvicorn cloud on 127.0.0.1, the cloud stitches the
frames and reads the page with the embedded OCR engine.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import wave
from pathlib import Path

import pytest

from darkread.core.paths import SAMPLE_RECORDING
from darkread.edge.io.recording import open_recording
from darkread.read import read_recording

pytestmark = pytest.mark.slow

# The shipped model reads the shipped sample with a CER of about 2 % (one character); the issue's
# bar is 5 %. A wrong gaze mapping or a broken stitch gives > 40 %.
MAX_SAMPLE_CER = 0.05


def test_shipped_sample_is_a_complete_recording() -> None:
    recording = open_recording(SAMPLE_RECORDING)
    assert recording.text and recording.raw_path.stat().st_size < 8 * 1024 * 1024


def test_read_recovers_the_printed_text(tmp_path: Path) -> None:
    """The every-window mode (research and evaluation): every frame inferred and sent."""
    result = read_recording(SAMPLE_RECORDING, out_dir=tmp_path, infer="every-window")
    assert result.reference is not None and result.cer is not None
    assert result.cer <= MAX_SAMPLE_CER, f"read {result.text!r} (CER {result.cer:.1%})"
    assert result.frames > 10 and result.messages_sent == result.frames
    assert 0 < result.events_foveated < result.events_in
    assert 0 < result.bytes_sent < result.raw_bytes
    assert Path(result.page_png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result.backend == "rapidocr+lexicon"


def test_the_default_on_change_mode_reads_the_sample_without_an_error(tmp_path: Path) -> None:
    """Fused views, stored with their grey levels and frame counts and stitched as that many
    frames, read the shipped sample without an error, from far fewer inferences and messages."""
    result = read_recording(SAMPLE_RECORDING, out_dir=tmp_path)
    assert result.reference is not None and result.backend == "rapidocr+lexicon"
    assert result.cer == 0.0, f"read {result.text!r} (CER {result.cer:.1%})"
    assert 0 < result.messages_sent < result.frames  # several frames behind each view


def test_read_json_has_the_per_stage_figures(tmp_path: Path) -> None:
    spoken = shutil.which("espeak-ng") is not None  # make speech-deps installs it when root
    say = ["--say-out", str(tmp_path / "said" / "answer.wav")] if spoken else []
    run = subprocess.run(
        [sys.executable, "-m", "darkread", "-q", "read", "--demo", "--json", "--out", str(tmp_path), *say],
        capture_output=True, text=True, timeout=300, check=True,
    )
    figures = json.loads(run.stdout)
    for key in ("text", "events_in", "events_foveated", "frames", "bytes_sent", "page_png", "backend", "seconds", "answer_ms"):
        assert key in figures, key
    assert 0 < figures["answer_ms"] < figures["seconds"] * 1000
    assert figures["text"].strip()
    if spoken:  # the answer spoken: a WAV as long as its words at 140 words per minute
        assert figures["speech_wav"] == say[1] and f"spoken answer written to {say[1]}" in run.stderr
        with wave.open(say[1]) as wav:
            seconds_per_word = wav.getnframes() / wav.getframerate() / len(figures["text"].split())
        assert 0.6 * 60 / 140 <= seconds_per_word <= 1.4 * 60 / 140


def test_say_out_must_name_a_wav_file(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "darkread", "read", "--demo", "--say-out", str(tmp_path / "answer.mp3")],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 1 and "give a .wav file name" in result.stderr


def test_read_of_a_missing_recording_is_a_clear_error(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "darkread", "read", str(tmp_path / "nowhere")],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 1
    assert "darkread: error:" in result.stderr and "nowhere" in result.stderr
