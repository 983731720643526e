"""The printable marker page: layout in millimetres, its files, and the simulator's view of it."""

from __future__ import annotations

import json
import re

import cv2
import numpy as np
import pytest

from darkread.models.synth.marker_page import (
    MASTER_PX_PER_MM,
    MarkerPageSpec,
    lay_out,
    layout_path_for,
    load_layout,
    mm_to_px,
    px_to_mm,
    text_lines,
    write_target,
)

SPEC = MarkerPageSpec(lines=("Reading in the dark", "with markers around"), marker_mm=10.0)


def test_mm_px_round_trip_and_pixel_convention():
    pts = np.array([[0.0, 0.0], [12.5, 3.25], [80.0, 40.0]])
    for s in (4.0, 5.2, 16.0):
        assert np.allclose(px_to_mm(mm_to_px(pts, s), s), pts)
    # pixel j covers [j, j + 1) / s: its centre sits at (j + 0.5) / s mm
    assert np.allclose(mm_to_px(np.array([[0.5 / 8.0, 2.5 / 8.0]]), 8.0), [[0.0, 2.0]])


def test_layout_markers_and_glyphs_sit_where_the_ink_is():
    page = lay_out(SPEC)
    assert len(page.markers) >= 4 and page.xheight_mm == pytest.approx(2.4, rel=0.02)
    s = MASTER_PX_PER_MM
    dictionary = SPEC.dictionary_obj()
    for marker_id, corners in page.markers.items():
        assert corners.shape == (4, 2)
        (left, top), (right, bottom) = corners[0], corners[2]
        assert right - left == pytest.approx(SPEC.marker_mm, abs=0.1) and bottom - top == pytest.approx(SPEC.marker_mm, abs=0.1)
        patch = page.ink[round(top * s) : round(bottom * s), round(left * s) : round(right * s)]
        # the drawn marker is the dictionary's marker of that id (decodes back to it)
        grey = np.pad(np.round(255 * (1 - patch)).astype(np.uint8), 20, constant_values=255)
        _, ids, _ = cv2.aruco.ArucoDetector(dictionary).detectMarkers(grey)
        assert ids is not None and ids.reshape(-1).tolist() == [marker_id]
    text = "".join(SPEC.lines).replace(" ", "")
    assert "".join(g["char"] for g in page.glyphs) == text
    for g in page.glyphs:
        x0, y0, x1, y1 = g["box_mm"]
        assert x1 > x0 and y1 > y0
        box = page.ink[int(y0 * s) : int(np.ceil(y1 * s)), int(x0 * s) : int(np.ceil(x1 * s))]
        assert box.max() > 0.5  # every glyph box holds ink
    # glyphs and markers do not overlap
    tx0, ty0, tx1, ty1 = page.text_box_mm
    for corners in page.markers.values():
        assert corners[:, 1].max() < ty0 or corners[:, 1].min() > ty1


def test_pdf_prints_at_the_stated_size_and_layout_reloads(tmp_path):
    page = lay_out(SPEC)
    pdf, layout = write_target(tmp_path / "page.pdf", page)
    assert layout == layout_path_for(pdf) == tmp_path / "page.layout.json"
    media = re.search(rb"/MediaBox \[ *0 0 ([\d.]+) ([\d.]+) *\]", pdf.read_bytes())
    assert media is not None
    w_pt, h_pt = float(media.group(1)), float(media.group(2))
    assert w_pt * 25.4 / 72 == pytest.approx(page.size_mm[0], abs=0.05)
    assert h_pt * 25.4 / 72 == pytest.approx(page.size_mm[1], abs=0.05)
    doc = json.loads(layout.read_text())
    assert doc["units"] == "mm" and len(doc["markers"]) == len(page.markers) and len(doc["glyphs"]) == len(page.glyphs)
    again = load_layout(layout)
    assert all(np.allclose(again.markers[i], page.markers[i]) for i in page.markers)

    png, _ = write_target(tmp_path / "page.png", page, dpi=200)
    from PIL import Image

    with Image.open(png) as im:
        assert im.info["dpi"][0] == pytest.approx(200, abs=0.5)
        assert im.size[0] / 200 * 25.4 == pytest.approx(page.size_mm[0], abs=0.2)


def test_bad_layouts_and_texts_say_what_is_wrong(tmp_path):
    with pytest.raises(FileNotFoundError, match="darkread train target"):
        load_layout(tmp_path / "missing.layout.json")
    (tmp_path / "bad.layout.json").write_text("{}")
    with pytest.raises(ValueError, match="page layout"):
        load_layout(tmp_path / "bad.layout.json")
    with pytest.raises(ValueError, match="empty"):
        text_lines("  \n \n")
    with pytest.raises(ValueError, match="pdf or .png"):
        write_target(tmp_path / "page.svg", lay_out(SPEC))
    assert text_lines("one two three four five", max_chars=9) == ("one two", "three", "four five")
