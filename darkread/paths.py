"""Where darkread finds its shipped files and, in a development checkout, ``../shared``."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_ROOT.parent
SAMPLE_RECORDING = PACKAGE_ROOT / "data" / "sample_recording"


def find_shared_data() -> Path | None:
    """The shared test-data folder (``$DARKREAD_SHARED_DATA`` or ``../shared/data``), if present."""
    env = os.environ.get("DARKREAD_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(REPO_ROOT.parent / "shared" / "data")
    for path in candidates:
        if path.is_dir():
            return path
    return None
