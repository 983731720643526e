"""Answers spoken aloud: text -> RIFF WAV with the offline ``espeak-ng`` engine.

The engine runs as a subprocess (one per answer, with a timeout) so a stuck or crashing
synthesiser never takes the service down with it, and no audio library is linked in. espeak-ng
writes its WAV to a pipe with placeholder sizes in the RIFF header (it cannot seek back); the
samples are read from the pipe into one buffer, which stops growing at the audio cap, and the
header's sizes are then written in place, so every player and ``wave`` reader sees the true length.
A long answer is spoken in parts (:func:`speech_parts`), each a bounded utterance.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import struct
import subprocess
import threading
import wave
from dataclasses import dataclass

from .errors import SpeechError, SpeechUnavailableError

WAV_MEDIA_TYPE = "audio/wav"
NOTHING_READ = "I could not read any text on the page yet."

# espeak-ng voice and language names: letters, digits, '-' and '_' (never an option-like '-...').
VOICE_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"
WAV_TYPES = frozenset({"audio/wav", "audio/x-wav", "audio/wave", "audio/vnd.wave"})
_HYPHENATED_BREAK = re.compile(r"(\w)-\n(\w)")
# A "word" longer than this is OCR debris, not speech: it is cut, which also bounds a part's text.
MAX_WORD_CHARS = 40
_SENTENCE_END = (".", "!", "?", ";", ":")
WAV_HEADER_BYTES = 44  # the canonical RIFF header espeak-ng writes: RIFF, WAVE, fmt (16 bytes), data
_READ_BYTES = 1 << 16
SPEECH_NICENESS = 10


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


def speech_parts(text: str, words_per_part: int) -> list[str]:
    """The answer as utterances of at most ``words_per_part`` words, each ending at a sentence end
    when one lies in its second half (a client pages through them with ``?part=N``)."""
    words = [word[:MAX_WORD_CHARS] for word in spoken_text(text).split()]
    parts: list[str] = []
    start = 0
    while start < len(words):
        end = min(len(words), start + words_per_part)
        if end < len(words):
            end = next((cut for cut in range(end, start + words_per_part // 2, -1)
                        if words[cut - 1].endswith(_SENTENCE_END)), end)  # fmt: skip
        parts.append(" ".join(words[start:end]))
        start = end
    return parts


@dataclass(frozen=True)
class SpokenWav:
    """A complete RIFF WAV, held once (``riff`` is the buffer the samples were read into)."""

    riff: bytearray
    info: WavInfo
    truncated: bool  # the audio cap cut it


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
    return bytes(synthesize_wav(text, voice, executable=executable, timeout_s=timeout_s).riff)


def synthesize_wav(text: str, voice: Voice, *, executable: str = "espeak-ng", timeout_s: float = 20.0,
                   max_seconds: float | None = None) -> SpokenWav:  # fmt: skip
    """Speak ``text`` into one buffer, at most ``max_seconds`` of audio (the engine is stopped
    there). Blocking: run it on the speech threads."""
    command = [engine_path(executable), "-v", voice.espeak_name, "-s", str(voice.rate_wpm), "--stdout"]
    try:
        process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    except OSError as exc:
        raise SpeechUnavailableError(f"speech engine {executable!r} could not run: {exc.strerror}") from None
    with contextlib.suppress(OSError):  # synthesis yields the CPU to the service's own work (store reads, asks)
        os.setpriority(os.PRIO_PROCESS, process.pid, SPEECH_NICENESS)
    timed_out = threading.Event()

    def expire() -> None:
        timed_out.set()
        process.kill()

    timer = threading.Timer(timeout_s, expire)
    timer.start()
    try:
        riff, truncated = _read_wav(process, text.encode(), max_seconds)
        stderr = process.stderr.read() if process.stderr else b""
        returncode = process.wait()
    finally:
        timer.cancel()
        if process.poll() is None:
            process.kill()
            process.wait()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()
    if timed_out.is_set():
        raise SpeechError(f"speech engine timed out after {timeout_s:g} s")
    if (returncode != 0 and not truncated) or riff is None:
        reason = stderr.decode(errors="replace").strip().splitlines()
        raise SpeechError(f"speech engine failed (exit {returncode}): {reason[-1] if reason else 'no output'}")
    info = patch_sizes(riff)
    return SpokenWav(riff, info, truncated)


def _read_wav(process: subprocess.Popen[bytes], text: bytes, max_seconds: float | None) -> tuple[bytearray | None, bool]:
    """The engine's WAV read into one buffer; stops (and stops the engine) at ``max_seconds``."""
    assert process.stdin is not None and process.stdout is not None  # both are pipes
    try:  # a part's text is a few kB: it fits the pipe, so writing first cannot wait on our reading
        process.stdin.write(text)
        process.stdin.close()
    except BrokenPipeError:
        return None, False
    riff = bytearray(process.stdout.read(WAV_HEADER_BYTES))
    if len(riff) < WAV_HEADER_BYTES:
        return (riff or None), False
    rate, channels, width = _format(riff)
    limit = None if max_seconds is None else WAV_HEADER_BYTES + int(max_seconds * rate) * channels * width
    while chunk := process.stdout.read1(_READ_BYTES):  # type: ignore[attr-defined]  # a BufferedReader (bufsize -1); typeshed says IO[bytes]
        riff += chunk
        if limit is not None and len(riff) >= limit:
            del riff[limit:]
            process.kill()
            return riff, True
    return riff, False


def _format(riff: bytes | bytearray) -> tuple[int, int, int]:
    """(sample rate, channels, bytes per sample) of a canonical 44-byte-header WAV."""
    if riff[:4] != b"RIFF" or riff[8:16] != b"WAVE" + b"fmt " or riff[36:40] != b"data":
        raise SpeechError("speech engine wrote no valid WAV: not a canonical RIFF header")
    _size, tag, channels, rate, _byte_rate, _align, bits = struct.unpack_from("<IHHIIHH", riff, 16)
    if tag != 1 or channels < 1 or rate < 1 or bits % 8:
        raise SpeechError(f"speech engine wrote no valid WAV: format {tag}, {channels} channels, {bits} bits")
    return rate, channels, bits // 8


def patch_sizes(riff: bytearray) -> WavInfo:
    """Write the true chunk sizes into a streamed WAV's header, in place (a partial last sample is dropped)."""
    rate, channels, width = _format(riff)
    frame_bytes = channels * width
    data = (len(riff) - WAV_HEADER_BYTES) // frame_bytes * frame_bytes
    del riff[WAV_HEADER_BYTES + data :]
    struct.pack_into("<I", riff, 4, len(riff) - 8)
    struct.pack_into("<I", riff, 40, data)
    return WavInfo(rate, channels, data // frame_bytes)


def with_true_sizes(riff: bytes) -> bytes:
    """A streamed WAV (placeholder chunk sizes) as a WAV whose header matches its samples."""
    fixed = bytearray(riff)
    patch_sizes(fixed)
    return bytes(fixed)


def wav_info(riff: bytes) -> WavInfo:
    with wave.open(io.BytesIO(riff)) as reader:
        return WavInfo(reader.getframerate(), reader.getnchannels(), reader.getnframes())
