"""The ``darkread`` command itself."""

from __future__ import annotations

import subprocess
import sys

from darkread.cli import build_parser, main


def test_help_lists_the_pipeline(capsys) -> None:
    assert main([]) == 2
    out = capsys.readouterr().out
    assert "ring buffer -> fovea -> voxel grid" in out


def test_module_entry_point_prints_version() -> None:
    result = subprocess.run([sys.executable, "-m", "darkread", "--version"], capture_output=True, text=True, check=True)
    assert result.stdout.startswith("darkread ")


def test_parser_builds_without_optional_components() -> None:
    assert build_parser().prog == "darkread"
