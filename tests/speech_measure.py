"""Measuring spoken answers: back to text with an offline recogniser, and what the signal holds.

The recogniser is PocketSphinx, whose wheel ships its US English model (nothing is downloaded);
it expects 16 kHz, so espeak-ng's 22.05 kHz is resampled with soxr first.
"""

from __future__ import annotations

import io
import shutil
import wave

import numpy as np
import pytest


def require_espeak() -> None:
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng is not installed (make system-deps installs it when run as root)")


def samples(riff: bytes) -> tuple[int, np.ndarray]:
    """(sample rate, mono int16 samples) of a WAV."""
    with wave.open(io.BytesIO(riff)) as reader:
        assert reader.getnchannels() == 1 and reader.getsampwidth() == 2
        return reader.getframerate(), np.frombuffer(reader.readframes(reader.getnframes()), np.int16)


def transcribe(riff: bytes) -> str:
    """What PocketSphinx hears in the WAV (lower case words)."""
    pocketsphinx = pytest.importorskip("pocketsphinx")
    soxr = pytest.importorskip("soxr")
    rate, pcm = samples(riff)
    # A narrower search than the default: half the time, the same words on espeak-ng's voices.
    decoder = pocketsphinx.Decoder(samprate=16000, loglevel="FATAL", maxhmmpf=3000, maxwpf=5)
    decoder.start_utt()
    decoder.process_raw(soxr.resample(pcm, rate, 16000).tobytes(), full_utt=True)
    decoder.end_utt()
    hypothesis = decoder.hyp()
    return hypothesis.hypstr if hypothesis is not None else ""


def band_share(pcm: np.ndarray, rate: int, low_hz: float = 80.0, high_hz: float = 5000.0) -> float:
    """Share of the signal's energy between ``low_hz`` and ``high_hz`` (speech sits there)."""
    spectrum = np.abs(np.fft.rfft(pcm.astype(np.float64))) ** 2
    freqs = np.fft.rfftfreq(pcm.size, 1.0 / rate)
    return float(spectrum[(freqs >= low_hz) & (freqs <= high_hz)].sum() / spectrum.sum())


def voiced_share(pcm: np.ndarray, rate: int, frame_s: float = 0.02) -> float:
    """Share of 20 ms frames within 30 dB of the loudest one: speech, not silence or a click."""
    n = int(rate * frame_s)
    frames = pcm[: pcm.size // n * n].astype(np.float64).reshape(-1, n)
    energy = (frames**2).mean(axis=1) + 1e-9
    return float((10 * np.log10(energy / energy.max()) > -30).mean())
