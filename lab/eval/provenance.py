"""How a report was made: date, commit, OCR backend, model, suite, and the commits its
recordings were evaluated at."""

from __future__ import annotations

import datetime as dt
import hashlib
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from darkread.lab.eval.results import RecordingResult


@dataclass
class ReportInfo:
    """What the report states about how it was made."""

    date: str = field(default_factory=lambda: dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"))
    commit: str = "unknown"
    backend: str = "local"
    model: str = ""
    suite: str = ""
    notes: list[str] = field(default_factory=list)


def git_commit(repo: str | Path | None = None) -> str:
    """Short hash of HEAD, ``unknown`` outside a git checkout."""
    cwd = Path(repo) if repo else Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], check=False, cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def model_digest(path: str | Path) -> str:
    """The first 12 hex digits of the model file's sha256: which weights a figure came from."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]


def describe_model(path: str | Path) -> str:
    path = Path(path)
    if not path.is_file():
        return f"{path.name} (missing)"
    digest = model_digest(path)
    stamp = dt.datetime.fromtimestamp(path.stat().st_mtime, dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return f"{path.name} (sha256 {digest}, {path.stat().st_size:,} bytes, {stamp})"


def run_commits(results: Sequence[RecordingResult], report_commit: str) -> str:
    """When the recordings were evaluated at other commits than the report's, say which and when."""
    commits = sorted({str(r.commit) for r in results if r.commit})
    if not commits or commits == [report_commit]:
        return ""
    stamps = sorted(str(r.evaluated) for r in results if r.evaluated)
    span = f", {stamps[0]} to {stamps[-1]}" if stamps else ""
    return f" (recordings evaluated at {', '.join(f'`{c}`' for c in commits)}{span})"
