"""The main job, end to end: ``darkread read`` on the shipped sample recording.

A real edge replays the recording into a real uvicorn cloud on 127.0.0.1, the cloud stitches the
frames and reads the page with the embedded OCR engine.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import wave
from pathlib import Path

import jiwer
import pytest
from speech_measure import require_espeak, transcribe

from darkread.cloud.speech import spoken_text
from darkread.core.paths import SAMPLE_RECORDING
from darkread.edge.inspect import inspect_path
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
    # "inside the fovea" is one figure, whichever command reports it
    assert result.fovea_event_fraction == inspect_path(SAMPLE_RECORDING, progress=False)["fovea_event_fraction"]


def test_read_a_bare_raw_file_with_its_gaze_csv_and_calibration(tmp_path: Path) -> None:
    raw = tmp_path / "elsewhere" / "events.raw"
    raw.parent.mkdir()
    shutil.copyfile(SAMPLE_RECORDING / "events.raw", raw)
    result = read_recording(raw, gaze_csv=SAMPLE_RECORDING / "general_eye_gaze.csv",
                            calibration=SAMPLE_RECORDING / "calibration.json")
    assert result.reference is None  # no text.txt beside it
    assert result.text == open_recording(SAMPLE_RECORDING).text.strip()


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


def test_say_out_without_out_writes_the_answer_spoken(tmp_path: Path) -> None:
    """No --out: the read runs in a scratch directory, and the spoken answer still lands at
    --say-out, where a recogniser hears the words that were read."""
    require_espeak()
    wav = tmp_path / "spoken" / "answer.wav"
    run = subprocess.run(
        [sys.executable, "-m", "darkread", "-q", "read", "--demo", "--json", "--say-out", str(wav)],
        capture_output=True, text=True, timeout=300, check=True,
    )
    figures = json.loads(run.stdout)
    assert figures["speech_wav"] == str(wav) and f"spoken answer written to {wav}" in run.stderr
    heard = transcribe(wav.read_bytes())
    # The sample's rare words ("sicken", "conformity") come back as near-homophones ("secret in",
    # "color with"): compared letter by letter, the answer is much nearer than unrelated sentences.
    said = jiwer.cer(_letters(spoken_text(figures["text"])), heard)
    unrelated = min(jiwer.cer(sentence, heard) for sentence in UNRELATED_SENTENCES)
    assert said <= 0.65 and said < unrelated - 0.15, f"heard {heard!r} for {figures['text']!r}"


UNRELATED_SENTENCES = (
    "a letter from my aunt said that the garden needs more water",
    "we are going to the market in the morning to buy bread",
    "the quick brown fox jumps over the lazy dog while reading",
)


def _letters(text: str) -> str:
    """Lower-case words without punctuation, as the recogniser writes them."""
    return " ".join(re.findall(r"[a-z']+", text.lower()))


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
