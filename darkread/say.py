"""Play a spoken answer on this machine's speakers, with whichever player the system has."""

from __future__ import annotations

import shutil
import subprocess
import wave
from pathlib import Path

PLAYERS = (("paplay", ()), ("aplay", ("-q",)), ("pw-play", ()))


def play_wav(path: Path) -> str:
    """Play ``path`` and return the player used; raises ``OSError`` with the reason when none could.

    The timeout is the WAV's own length plus a margin, so a player stuck on a missing sound
    device does not hang the command.
    """
    with wave.open(str(path)) as reader:
        timeout_s = reader.getnframes() / reader.getframerate() + 10
    failures: list[str] = []
    for name, args in PLAYERS:
        player = shutil.which(name)
        if player is None:
            continue
        try:
            done = subprocess.run([player, *args, str(path)], capture_output=True, timeout=timeout_s, check=False)
        except subprocess.TimeoutExpired:
            failures.append(f"{name} timed out")
            continue
        if done.returncode == 0:
            return name
        reason = done.stderr.decode(errors="replace").strip().splitlines()
        failures.append(f"{name}: {reason[-1] if reason else f'exit {done.returncode}'}")
    if not failures:
        raise OSError("no audio player found (paplay, aplay or pw-play)")
    raise OSError("; ".join(failures))
