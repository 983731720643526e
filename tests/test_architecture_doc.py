"""docs/architecture.md names only what exists: every repository path and darkread module in it."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
ENTRY_POINT_GROUP = "darkread.commands"  # a name in pyproject.toml, not a module
TOP_FOLDERS = ("darkread/", "edge/", "cloud/", "proto/", "stitch/", "models/", "lab/", "docs/", "tests/")


def named_paths(text: str) -> set[str]:
    """Backticked repository paths: ``edge/ring.py``, ``cloud/store/``."""
    return {token for token in re.findall(r"`([\w./]+)`", text) if token.startswith(TOP_FOLDERS)}


def named_modules(text: str) -> set[str]:
    """Backticked dotted darkread names: ``darkread.edge``, ``darkread.core``."""
    return {token for token in re.findall(r"`(darkread(?:\.\w+)+)`", text)} - {ENTRY_POINT_GROUP}


def test_every_path_the_architecture_page_names_exists() -> None:
    text = DOC.read_text(encoding="utf-8")
    paths = named_paths(text)
    assert len(paths) > 40  # the module map names its modules with their folders
    assert sorted(p for p in paths if not (ROOT / p).exists()) == []


def test_every_module_the_architecture_page_names_imports() -> None:
    modules = named_modules(DOC.read_text(encoding="utf-8"))
    assert {"darkread.core", "darkread.lab", "darkread.edge", "darkread.cloud"} <= modules
    assert sorted(m for m in modules if importlib.util.find_spec(m) is None) == []
