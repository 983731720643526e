"""Spoken answers: the time and the memory to speak a 300-word answer (one part at the defaults).

Measured in a child process of its own, so its peak resident set (VmHWM) is the interpreter, the
speech module and one answer's WAV, nothing else of the benchmark run: the reference is the same
child's peak before it spoke, and a second child speaking it the way the service did before
(``subprocess.run(capture_output=True)``, ``wave`` reading the samples and writing a new WAV: the
audio held three times). The time is ``synthesize_wav`` (espeak-ng as a subprocess, the WAV read
into one buffer and its header patched), against that earlier way.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

from darkread.lab.bench import BenchContext, Figure

WORDS = 300
SENTENCE = "The reader moves along the line and the words come back one after another in the dark."

_CHILD = """
import io, json, subprocess, sys, time, wave
from pathlib import Path
from darkread.cloud.settings import Settings
from darkread.cloud.speech import speech_parts, synthesize_wav

def high_water_mb():
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines())
    return int(fields["VmHWM"].split()[0]) / 1024

settings = Settings(_env_file=None)
text = sys.stdin.read()
runs, mode = int(sys.argv[1]), sys.argv[2]

def held_three_times(part, voice, executable):
    command = [executable, "-v", voice.espeak_name, "-s", str(voice.rate_wpm), "--stdout"]
    done = subprocess.run(command, input=part.encode(), capture_output=True, check=True)
    with wave.open(io.BytesIO(done.stdout)) as source:
        params = source.getparams()
        samples = source.readframes(params.nframes)
    out = io.BytesIO()
    with wave.open(out, "wb") as target:
        target.setparams(params)
        target.writeframes(samples)
    return out.getvalue()
(part,) = speech_parts(text, max(settings.speech_part_words, len(text.split())))
before = high_water_mb()
times = []
for _ in range(runs):
    started = time.perf_counter()
    if mode == "bounded":
        wav = synthesize_wav(part, settings.voice(), executable=settings.speech_engine, timeout_s=60,
                             max_seconds=settings.speech_max_seconds)
        seconds, size = wav.info.seconds, len(wav.riff)
    else:
        riff = held_three_times(part, settings.voice(), settings.speech_engine)
        seconds, size = (len(riff) - 44) / 2 / 22050, len(riff)
    times.append(time.perf_counter() - started)
print(json.dumps({"ms": sorted(times)[len(times) // 2] * 1000, "before_mb": before, "peak_mb": high_water_mb(),
                  "seconds": seconds, "bytes": size}))
"""


def answer_text(words: int) -> str:
    sentence = SENTENCE.split()
    return " ".join(sentence[i % len(sentence)] for i in range(words))


def _speak_in_a_child(text: str, runs: int, mode: str) -> dict[str, float]:
    child = subprocess.run([sys.executable, "-c", _CHILD, str(runs), mode], input=text, capture_output=True, text=True,
                           check=True, timeout=600)  # fmt: skip
    return json.loads(child.stdout)


def run(ctx: BenchContext) -> list[Figure]:
    if shutil.which("espeak-ng") is None:
        ctx.notes.append("speech: espeak-ng is not installed (make speech-deps), skipped")
        return []
    runs = ctx.runs(7, 3)
    text = answer_text(WORDS)
    measured = _speak_in_a_child(text, runs, "bounded")
    before = _speak_in_a_child(text, runs, "held-three-times")
    return [
        Figure(
            key="speech_300_words_ms", value=measured["ms"],
            label=f"spoken answer, {WORDS} words ({measured['seconds']:.0f} s of audio) [ms]",
            reference=f"held three times (as before): {before['ms']:.0f} ms", goal="<= the earlier way",
        ),
        Figure(
            key="speech_300_words_peak_rss_mb", value=measured["peak_mb"],
            label=f"spoken answer, {WORDS} words: peak RSS of a process speaking it [MB]",
            reference=f"before speaking {measured['before_mb']:.0f} MB; held three times (as before): peak "
            f"{before['peak_mb']:.0f} MB; the WAV {measured['bytes'] / 2**20:.1f} MB", goal="<= the earlier way",
        ),
    ]  # fmt: skip
