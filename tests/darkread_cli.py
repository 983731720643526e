"""Run the real `darkread` command in a subprocess, and check the one-line error contract."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def darkread(*argv: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    command = Path(sys.executable).with_name("darkread")
    prefix = [str(command)] if command.is_file() else [sys.executable, "-m", "darkread"]
    return subprocess.run([*prefix, "-q", *argv], capture_output=True, text=True, timeout=timeout, check=False)


def assert_one_error_line(result: subprocess.CompletedProcess[str], mentions: str) -> None:
    assert result.returncode == 1, result.stderr
    lines = [line for line in result.stderr.strip().splitlines() if line.startswith("darkread:")]
    assert len(lines) == 1 and lines[0].startswith("darkread: error: ") and mentions in lines[0], result.stderr
    assert "Traceback" not in result.stderr
