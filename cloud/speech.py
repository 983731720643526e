"""Answers spoken aloud: text -> RIFF WAV with the offline ``espeak-ng`` engine.

The engine runs as a subprocess (one per answer, with a timeout) so a stuck or crashing
synthesiser never takes the service down with it, and no audio library is linked in. espeak-ng
writes its WAV to a pipe with placeholder sizes in the RIFF header (it cannot seek back); the
header is rewritten here so every player and ``wave`` reader sees the true length.
"""

from __future__ import annotations

import io
import re
import shutil
import subprocess
import wave
from dataclasses import dataclass

from .errors import SpeechError, SpeechUnavailableError

WAV_MEDIA_TYPE = "audio/wav"
NOTHING_READ = "I could not read any text on the page yet."

# espeak-ng voice and language names: letters, digits, '-' and '_' (never an option-like '-...').
VOICE_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"
WAV_TYPES = frozenset({"audio/wav", "audio/x-wav", "audio/wave", "audio/vnd.wave"})
_HYPHENATED_BREAK = re.compile(r"(\w)-\n(\w)")


@dataclass(frozen=True)
class Voice:
    """How answers sound: espeak-ng's language (``en-us``), an optional variant (``f3``), words per minute.

    The names are validated where they are configured (``Settings``, ``VOICE_NAME_PATTERN``).
    """

    language: str = "en-us"
    variant: str = "f2"
    rate_wpm: int = 140

    @property
    def espeak_name(self) -> str:
        return f"{self.language}+{self.variant}" if self.variant else self.language


@dataclass(frozen=True)
class WavInfo:
    """What a WAV holds, for logs, headers and checks."""

    sample_rate: int
    channels: int
    frames: int

    @property
    def seconds(self) -> float:
        return self.frames / self.sample_rate


def wants_wav(accept: str | None, format_: str | None = None) -> bool:
    """True when the client asked for speech: ``?format=wav``, or a WAV type preferred over JSON in Accept."""
    if format_ is not None:
        return format_ == "wav"
    best_wav = best_json = 0.0
    for media_range in (accept or "").split(","):
        media_type, *params = (part.strip() for part in media_range.split(";"))
        quality = 1.0
        for param in params:
            name, _, value = param.partition("=")
            if name.strip() == "q":
                try:
                    quality = float(value)
                except ValueError:
                    quality = 0.0
        if media_type.lower() in WAV_TYPES:
            best_wav = max(best_wav, quality)
        elif media_type.lower() == "application/json":
            best_json = max(best_json, quality)
    return best_wav > 0 and best_wav >= best_json


def spoken_text(text: str) -> str:
    """The answer as one utterance: printed line breaks are not pauses, hyphenated words are rejoined.

    OCR text keeps the page's line breaks ("they\\nsicken"); read aloud they would cut sentences
    mid-phrase, and a word split at a line end ("confor-\\nmity") would be spelled as two.
    """
    joined = _HYPHENATED_BREAK.sub(r"\1\2", text.strip())
    words = " ".join(joined.split())
    return words or NOTHING_READ


def engine_path(executable: str) -> str:
    """The engine's absolute path, or a one-line reason why there is none."""
    found = shutil.which(executable)
    if found is None:
        raise SpeechUnavailableError(
            f"speech engine {executable!r} is not installed (Debian: apt-get install espeak-ng, or make system-deps)"
        )
    return found


def synthesize(text: str, voice: Voice, *, executable: str = "espeak-ng", timeout_s: float = 20.0) -> bytes:
    """Speak ``text`` (already prepared with :func:`spoken_text`) into a complete RIFF WAV. Blocking."""
    command = [engine_path(executable), "-v", voice.espeak_name, "-s", str(voice.rate_wpm), "--stdout"]
    try:
        done = subprocess.run(command, input=text.encode(), capture_output=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired:
        raise SpeechError(f"speech engine timed out after {timeout_s:g} s") from None
    except OSError as exc:
        raise SpeechUnavailableError(f"speech engine {executable!r} could not run: {exc.strerror}") from None
    if done.returncode != 0 or not done.stdout:
        reason = done.stderr.decode(errors="replace").strip().splitlines()
        raise SpeechError(f"speech engine failed (exit {done.returncode}): {reason[-1] if reason else 'no output'}")
    return with_true_sizes(done.stdout)


def with_true_sizes(riff: bytes) -> bytes:
    """Rewrite a streamed WAV (placeholder chunk sizes) as a WAV whose header matches its samples."""
    try:
        with wave.open(io.BytesIO(riff)) as source:
            params = source.getparams()
            samples = source.readframes(params.nframes)
    except (wave.Error, EOFError) as exc:
        raise SpeechError(f"speech engine wrote no valid WAV: {exc}") from None
    out = io.BytesIO()
    with wave.open(out, "wb") as target:
        target.setnchannels(params.nchannels)
        target.setsampwidth(params.sampwidth)
        target.setframerate(params.framerate)
        target.writeframes(samples)
    return out.getvalue()


def wav_info(riff: bytes) -> WavInfo:
    with wave.open(io.BytesIO(riff)) as reader:
        return WavInfo(reader.getframerate(), reader.getnchannels(), reader.getnframes())
