"""Where darkread finds its shipped files."""

from __future__ import annotations

from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
SAMPLE_RECORDING = PACKAGE_ROOT / "data" / "sample_recording"
