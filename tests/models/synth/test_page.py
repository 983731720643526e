from __future__ import annotations

import numpy as np
import pytest

from darkread.models.synth.fonts import faces_for
from darkread.models.synth.page import render_page
from darkread.models.synth.text import TEXT_KINDS, make_lines, paragraphs_for


@pytest.mark.parametrize("kind", TEXT_KINDS)
def test_lines_fit_and_are_ascii(kind):
    rng = np.random.default_rng(4)
    lines = make_lines(kind, 6, 30, rng)
    assert 1 <= len(lines) <= 6
    assert all(0 < len(line) <= 30 and line == line.strip() and line.isascii() for line in lines)


def test_validation_texts_are_not_training_texts():
    train, val = set(paragraphs_for("train")), set(paragraphs_for("val"))
    assert train and val and not train & val


@pytest.mark.parametrize("face", faces_for("all"), ids=lambda f: f.name)
def test_render_hits_the_requested_xheight_and_is_antialiased(face):
    page = render_page(["xxxx nox"], face, 10.0, 1e-4)
    assert abs(page.xheight_tex - 10.0) < 0.4
    cov = page.coverage
    assert cov.max() > 0.99 and ((cov > 0.05) & (cov < 0.95)).sum() > 20  # grey edge texels
    rows = np.flatnonzero(page.ink_mask()[:, :].any(axis=1))
    assert abs((rows.max() - rows.min() + 1) - 10.0) <= 1.5  # 'x', 'n', 'o' span one x-height
    assert len(page.char_x[0]) == len("xxxx nox") and np.all(np.diff(page.char_x[0]) > 0)
