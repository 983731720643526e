"""A printable page for adapting the model to a real sensor: text with ArUco markers around it.

The page is laid out once, at a master resolution, with the synthesiser's own text renderer
(``page.render_page``) and the calibration code's marker dictionary (``BoardSpec``); every other
use (the PDF or PNG a user prints, the simulator's texture, the annotator's ink targets) is a
resampling of that master, so all of them agree with the layout to a fraction of a pixel.

Page frame: millimetres, origin at the sheet's top-left corner, x to the right, y down. A master
pixel (i, j) covers x in [j, j + 1) / px_per_mm, y in [i, i + 1) / px_per_mm.

``page.layout.json`` (written next to the PDF/PNG) holds everything needed to re-create the page
and to annotate recordings of it: the text lines, font, sizes, the markers (id and corners, TL TR
BR BL as ``cv2.aruco`` reports them) and every glyph's ink box.
"""

from __future__ import annotations

import json
import math
import textwrap
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from darkread.core.json_file import read_json_file
from darkread.edge.calibrate.markers import BoardSpec
from darkread.models.synth.fonts import face_by_name
from darkread.models.synth.page import render_page

LAYOUT_SUFFIX = ".layout.json"
MASTER_PX_PER_MM = 16.0  # 406 dpi: fine enough for print and for every texture the simulator needs
LAYOUT_VERSION = 1


@dataclass(frozen=True)
class MarkerPageSpec:
    """What is printed: the text and how big; markers in a row above and a row below the text."""

    lines: tuple[str, ...]
    font: str = "DejaVu Sans"
    xheight_mm: float = 2.4  # about 12 pt body text
    line_spacing: float = 1.5  # line pitch / font size
    marker_mm: float = 12.0  # side of each ArUco marker (black border included)
    gap_mm: float = 5.0  # white space between the markers and the text
    margin_mm: float = 8.0  # white space around everything (the markers' quiet zone)
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        if not self.lines or not any(line.strip() for line in self.lines):
            raise ValueError("a marker page needs some text")
        if self.xheight_mm <= 0 or self.marker_mm <= 0 or self.gap_mm < 0 or self.margin_mm < 0:
            raise ValueError("x-height, marker size, gap and margin must be positive")
        face_by_name(self.font)  # raises ValueError for an unknown face
        BoardSpec("grid", 2, 2, 2.0, 1.0, self.dictionary)  # raises for an unknown dictionary

    def dictionary_obj(self) -> cv2.aruco.Dictionary:
        return BoardSpec("grid", 2, 2, 2.0, 1.0, self.dictionary).aruco_dictionary()


@dataclass
class MarkerPage:
    """A laid-out page: its master ink raster (1 = ink) and the layout in millimetres."""

    spec: MarkerPageSpec
    ink: np.ndarray  # float32 [H, W] coverage at MASTER_PX_PER_MM
    size_mm: tuple[float, float]  # sheet (width, height)
    markers: dict[int, np.ndarray]  # id -> corners (4, 2) mm, TL TR BR BL
    glyphs: list[dict]  # {"line", "char", "box_mm": [x0, y0, x1, y1]}
    text_box_mm: tuple[float, float, float, float]
    line_y_mm: list[float]  # x-height centre of each line
    char_x_mm: list[list[float]] = field(default_factory=list)  # per line: centre of each character
    xheight_mm: float = 0.0  # as rendered (font sizes are whole master pixels)

    @property
    def px_per_mm(self) -> float:
        return MASTER_PX_PER_MM

    def layout(self) -> dict:
        """The JSON document written as ``page.layout.json``."""
        return {
            "version": LAYOUT_VERSION,
            "units": "mm",
            "frame": "origin at the sheet's top-left corner, x right, y down",
            "spec": {**asdict(self.spec), "lines": list(self.spec.lines)},
            "size_mm": [round(v, 4) for v in self.size_mm],
            "xheight_mm": round(self.xheight_mm, 4),
            "text_box_mm": [round(v, 4) for v in self.text_box_mm],
            "line_y_mm": [round(v, 4) for v in self.line_y_mm],
            "markers": [{"id": int(i), "corners_mm": np.round(c, 4).tolist()} for i, c in sorted(self.markers.items())],
            "glyphs": self.glyphs,
        }

    def marker_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(ids [N], corners [N, 4, 2] mm) of the markers."""
        ids = np.array(sorted(self.markers), dtype=np.int64)
        return ids, np.stack([self.markers[int(i)] for i in ids])

    def ink_at(self, px_per_mm: float) -> np.ndarray:
        """Ink coverage resampled to ``px_per_mm`` (area average; same page frame convention)."""
        return resample(self.ink, MASTER_PX_PER_MM, px_per_mm)

    def marker_area_at(self, px_per_mm: float, margin_mm: float) -> np.ndarray:
        """Coverage (float32, the ``ink_at`` raster's shape and frame) of every marker's square grown
        by ``margin_mm`` on each side: the part of the page that is markers, not text."""
        area = np.zeros_like(self.ink_at(px_per_mm))
        for corners in self.markers.values():
            (x0, y0), (x1, y1) = corners.min(axis=0) - margin_mm, corners.max(axis=0) + margin_mm
            c0, r0 = np.floor(np.array([x0, y0]) * px_per_mm).astype(int)  # texel j covers [j, j+1) / px_per_mm
            c1, r1 = np.ceil(np.array([x1, y1]) * px_per_mm).astype(int)
            area[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = 1.0
        return area


def resample(image: np.ndarray, from_px_per_mm: float, to_px_per_mm: float) -> np.ndarray:
    """Area resampling keeping the pixel-edge convention: pixel j covers [j, j+1) / px_per_mm."""
    if math.isclose(from_px_per_mm, to_px_per_mm):
        return image.astype(np.float32)
    scale = to_px_per_mm / from_px_per_mm
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    # no dsize: OpenCV then scales by exactly fx, fy (a rounded dsize would stretch the page slightly)
    return cv2.resize(image.astype(np.float32), None, fx=scale, fy=scale, interpolation=interp)


def mm_to_px(points_mm: np.ndarray, px_per_mm: float) -> np.ndarray:
    """Page mm -> raster pixel coordinates (pixel centres at integers: x_px = x_mm * s - 0.5)."""
    return np.asarray(points_mm, dtype=np.float64) * px_per_mm - 0.5


def px_to_mm(points_px: np.ndarray, px_per_mm: float) -> np.ndarray:
    """Raster pixel coordinates -> page mm (inverse of ``mm_to_px``)."""
    return (np.asarray(points_px, dtype=np.float64) + 0.5) / px_per_mm


def marker_columns(text_width_mm: float, marker_mm: float) -> int:
    """Markers per row: at least 2 (the corners), one more for every ~3 marker widths of text."""
    return max(2, int(round(text_width_mm / (3.0 * marker_mm))) + 1)


def lay_out(spec: MarkerPageSpec) -> MarkerPage:
    """Render the text and place the markers (pure function of the spec)."""
    return _lay_out_cached(spec)


@lru_cache(maxsize=8)
def _lay_out_cached(spec: MarkerPageSpec) -> MarkerPage:
    s = MASTER_PX_PER_MM
    face = face_by_name(spec.font)
    text = render_page(list(spec.lines), face, spec.xheight_mm * s, 1e-3 / s, line_spacing=spec.line_spacing,
                       margin_xheights=1.0)
    tx0, ty0, tx1, ty1 = text.text_box  # texels of the text image (x-height based vertical extent)
    ink_rows = np.flatnonzero(text.coverage.max(axis=1) > 0.02)
    ty0 = min(ty0, float(ink_rows[0])) if ink_rows.size else ty0
    ty1 = max(ty1, float(ink_rows[-1] + 1)) if ink_rows.size else ty1
    text_w_mm, text_h_mm = (tx1 - tx0) / s, (ty1 - ty0) / s
    n_cols = marker_columns(text_w_mm, spec.marker_mm)
    row_w_mm = max(text_w_mm, n_cols * spec.marker_mm * 1.5)
    width_mm = row_w_mm + 2 * spec.margin_mm
    height_mm = 2 * spec.margin_mm + 2 * spec.marker_mm + 2 * spec.gap_mm + text_h_mm
    width_px, height_px = int(math.ceil(width_mm * s)), int(math.ceil(height_mm * s))
    ink = np.zeros((height_px, width_px), np.float32)
    # text: its block starts at (left, top) of the area between the marker rows, centred horizontally
    text_left_mm = spec.margin_mm + (row_w_mm - text_w_mm) / 2
    text_top_mm = spec.margin_mm + spec.marker_mm + spec.gap_mm
    ox = int(round(text_left_mm * s - tx0))  # whole master pixels: the text raster is pasted, not resampled
    oy = int(round(text_top_mm * s - ty0))
    h, w = text.coverage.shape
    y0, x0 = max(oy, 0), max(ox, 0)
    y1, x1 = min(oy + h, height_px), min(ox + w, width_px)
    ink[y0:y1, x0:x1] = np.maximum(ink[y0:y1, x0:x1], text.coverage[y0 - oy : y1 - oy, x0 - ox : x1 - ox])
    # markers: a row above and a row below, evenly spread over the row width
    side_px = int(round(spec.marker_mm * s))
    dictionary = spec.dictionary_obj()
    markers: dict[int, np.ndarray] = {}
    xs_mm = np.linspace(spec.margin_mm, spec.margin_mm + row_w_mm - side_px / s, n_cols)
    rows_mm = (spec.margin_mm, height_mm - spec.margin_mm - side_px / s)
    if 2 * n_cols > dictionary.bytesList.shape[0]:
        raise ValueError(f"{spec.dictionary} has only {dictionary.bytesList.shape[0]} markers; the page needs {2 * n_cols}")
    marker_id = 0
    for top_mm in rows_mm:
        for left_mm in xs_mm:
            px, py = int(round(left_mm * s)), int(round(top_mm * s))
            image = cv2.aruco.generateImageMarker(dictionary, marker_id, side_px, borderBits=1)
            ink[py : py + side_px, px : px + side_px] = 1.0 - image.astype(np.float32) / 255.0
            left, top, right, bottom = px / s, py / s, (px + side_px) / s, (py + side_px) / s
            markers[marker_id] = np.array([[left, top], [right, top], [right, bottom], [left, bottom]], dtype=np.float64)
            marker_id += 1
    glyphs = []
    for line_no, boxes in enumerate(text.glyph_boxes):
        for ch, gx0, gy0, gx1, gy1 in boxes:
            box = [(gx0 + ox) / s, (gy0 + oy) / s, (gx1 + ox) / s, (gy1 + oy) / s]
            glyphs.append({"line": line_no, "char": ch, "box_mm": [round(v, 4) for v in box]})
    return MarkerPage(
        spec=spec,
        ink=ink,
        size_mm=(width_px / s, height_px / s),
        markers=markers,
        glyphs=glyphs,
        text_box_mm=((tx0 + ox) / s, (ty0 + oy) / s, (tx1 + ox) / s, (ty1 + oy) / s),
        line_y_mm=[float((y + oy) / s) for y in text.line_y],
        char_x_mm=[[float((x + ox) / s) for x in xs] for xs in text.char_x],
        xheight_mm=float(text.xheight_tex / s),
    )


# -- files ---------------------------------------------------------------------------------------


def layout_path_for(out: str | Path) -> Path:
    """``page.pdf`` -> ``page.layout.json`` (beside it)."""
    out = Path(out)
    return out.with_name(out.stem + LAYOUT_SUFFIX)


def save_layout(path: str | Path, page: MarkerPage) -> Path:
    path = Path(path)
    path.write_text(json.dumps(page.layout(), indent=1) + "\n", encoding="utf-8")
    return path


def spec_from_layout(doc: dict) -> MarkerPageSpec:
    try:
        spec = dict(doc["spec"])
        spec["lines"] = tuple(str(line) for line in spec["lines"])
        return MarkerPageSpec(**spec)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"page layout is incomplete or malformed: {exc!r}") from exc


def load_layout(path: str | Path) -> MarkerPage:
    """Re-create a page from its ``page.layout.json`` (checks that the file's markers match)."""
    path = Path(path)
    doc = read_json_file(path, "page layout", missing="make one with `darkread train target`", not_found=FileNotFoundError)
    if not isinstance(doc, dict) or doc.get("version") != LAYOUT_VERSION:
        raise ValueError(f"{path}: not a version-{LAYOUT_VERSION} page layout")
    page = lay_out(spec_from_layout(doc))
    written = {int(m["id"]): np.asarray(m["corners_mm"], float) for m in doc.get("markers", [])}
    if set(written) != set(page.markers) or any(np.abs(written[i] - page.markers[i]).max() > 1e-3 for i in written):
        raise ValueError(f"{path}: its markers do not match the page its spec lays out (edited by hand?)")
    return page


def write_png(path: str | Path, page: MarkerPage, dpi: float = 300.0) -> Path:
    """The page as a grey PNG at ``dpi`` (its pHYs chunk says so, so it prints at size)."""
    from PIL import Image

    px_per_mm = dpi / 25.4
    grey = np.round(255.0 * (1.0 - np.clip(page.ink_at(px_per_mm), 0.0, 1.0))).astype(np.uint8)
    Image.fromarray(grey, mode="L").save(path, dpi=(dpi, dpi))
    return Path(path)


def write_pdf(path: str | Path, page: MarkerPage) -> Path:
    """The page as a one-page PDF whose media box is the sheet size: print at 100 % ("actual size")."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    w_mm, h_mm = page.size_mm
    fig = Figure(figsize=(w_mm / 25.4, h_mm / 25.4))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    grey = np.round(255.0 * (1.0 - np.clip(page.ink, 0.0, 1.0))).astype(np.uint8)
    ax.imshow(grey, cmap="gray", vmin=0, vmax=255, extent=(0.0, w_mm, h_mm, 0.0), interpolation="none", aspect="auto")
    ax.set_xlim(0.0, w_mm)
    ax.set_ylim(h_mm, 0.0)
    fig.savefig(path, format="pdf", dpi=MASTER_PX_PER_MM * 25.4)
    return Path(path)


def write_target(out: str | Path, page: MarkerPage, *, dpi: float = 300.0) -> tuple[Path, Path]:
    """``out`` (.pdf or .png) and its layout beside it; returns both paths."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".pdf", ".png"):
        raise ValueError(f"{out}: the target is written as .pdf or .png")
    out.parent.mkdir(parents=True, exist_ok=True)
    (write_pdf if suffix == ".pdf" else lambda p, pg: write_png(p, pg, dpi))(out, page)
    return out, save_layout(layout_path_for(out), page)


def text_lines(text: str, max_chars: int = 48) -> tuple[str, ...]:
    """Printed lines of a text file: its own lines, long ones wrapped at word boundaries."""

    lines: list[str] = []
    for raw in text.splitlines():
        raw = " ".join(raw.split())
        if raw:
            lines.extend(textwrap.wrap(raw, max_chars) or [raw])
    if not lines:
        raise ValueError("the text is empty")
    return tuple(lines)
