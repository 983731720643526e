"""Where a development checkout finds ``../shared`` (real recordings and gaze data for the lab and the tests)."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]


def find_shared_data() -> Path | None:
    """The shared test-data folder (``$DARKREAD_SHARED_DATA`` or ``../shared/data``), if present."""
    env = os.environ.get("DARKREAD_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(REPO_ROOT.parent / "shared" / "data")
    for path in candidates:
        if path.is_dir():
            return path
    return None
