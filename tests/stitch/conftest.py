"""Fixtures of the stitcher tests: the synthetic page and reading passes over it (``reading_factory.py``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("reading_factory", Path(__file__).with_name("reading_factory.py"))
assert _spec is not None and _spec.loader is not None
scan = importlib.util.module_from_spec(_spec)
sys.modules["reading_factory"] = scan
_spec.loader.exec_module(scan)


@pytest.fixture(scope="session")
def rendered_page():
    return scan.render_page()


@pytest.fixture(scope="session")
def short_page():
    """Five short lines: a quick page for the readings that deliver many frames."""
    return scan.render_page(scan.PARAGRAPH[:140], width_chars=30)


@pytest.fixture(scope="session")
def reading(rendered_page):
    return scan.simulate_reading(rendered_page, seed=0)


@pytest.fixture(scope="session")
def stitched(reading):
    from darkread.stitch import stitch_page

    return stitch_page(reading.frames)
