"""Printed pages: text rendered with Pillow at high resolution and area-downsampled.

A page is a texture (one texel = ``texel_m`` metres on paper) holding the ink coverage in [0, 1]
(anti-aliased), plus where every printed character sits, for the reading scanpath.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from darkread.models.synth.fonts import FontFace

SUPERSAMPLE = 4


@dataclass
class PrintedPage:
    """A rendered printed page: ink coverage per texel and where its lines and characters sit."""

    lines: list[str]
    font: str
    coverage: np.ndarray  # float32 [H, W] ink coverage 0..1 (1 = ink), anti-aliased
    texel_m: float  # metres per texel on the paper
    xheight_tex: float  # lower-case x-height in texels
    line_y: np.ndarray  # [n_lines] texel row of each line's x-height centre
    char_x: list[np.ndarray] = field(default_factory=list)  # per line: texel column of each character centre
    text_box: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # x0, y0, x1, y1 of the text, texels
    # per line: (char, x0, y0, x1, y1) texels, ink extent
    glyph_boxes: list[list[tuple[str, float, float, float, float]]] = field(default_factory=list)

    @property
    def text(self) -> str:
        """The text exactly as printed: one line per printed line, no trailing newline."""
        return "\n".join(self.lines)

    @property
    def text_center_tex(self) -> np.ndarray:
        x0, y0, x1, y1 = self.text_box
        return np.array([(x0 + x1) / 2, (y0 + y1) / 2])

    def ink_mask(self) -> np.ndarray:
        """The ideal binary print (uint8, 1 = ink)."""
        return (self.coverage >= 0.5).astype(np.uint8)


@lru_cache(maxsize=64)
def _font(path: str, size: int) -> ImageFont.FreeTypeFont:
    return ImageFont.truetype(path, size)


@lru_cache(maxsize=64)
def xheight_ratio(path: str) -> float:
    """x-height as a fraction of the font size (measured on the glyph 'x')."""
    size = 200
    font = _font(path, size)
    _, top, _, bottom = font.getbbox("x", anchor="ls")
    return (bottom - top) / size


def render_page(
    lines: list[str],
    face: FontFace,
    xheight_tex: float,
    texel_m: float,
    *,
    line_spacing: float = 1.4,
    margin_xheights: float = 12.0,
) -> PrintedPage:
    """Render ``lines`` left-aligned so that the x-height is ``xheight_tex`` texels."""
    path = str(face.path)
    ratio = xheight_ratio(path)
    size_px = max(4, int(round(xheight_tex / ratio * SUPERSAMPLE)))
    font = _font(path, size_px)
    xh_ss = ratio * size_px  # actual x-height at supersampled resolution
    pitch_ss = line_spacing * size_px
    margin_ss = margin_xheights * xh_ss
    widths = [font.getlength(line) for line in lines]
    width_ss = int(np.ceil(max(widths) + 2 * margin_ss))
    height_ss = int(np.ceil(pitch_ss * (len(lines) - 1) + size_px + 2 * margin_ss))
    width_ss += (-width_ss) % SUPERSAMPLE
    height_ss += (-height_ss) % SUPERSAMPLE
    image = Image.new("L", (width_ss, height_ss), 0)
    draw = ImageDraw.Draw(image)
    baselines = margin_ss + size_px * 0.8 + pitch_ss * np.arange(len(lines))
    char_x, glyph_boxes = [], []
    for line, baseline in zip(lines, baselines):
        draw.text((margin_ss, float(baseline)), line, fill=255, font=font, anchor="ls")
        edges = np.array([font.getlength(line[:k]) for k in range(len(line) + 1)])
        char_x.append(((edges[:-1] + edges[1:]) / 2 + margin_ss) / SUPERSAMPLE)
        glyph_boxes.append(_glyph_boxes(line, font, edges, margin_ss, float(baseline)))
    small = image.reduce(SUPERSAMPLE)  # box filter = area downsampling
    coverage = np.asarray(small, dtype=np.float32) / 255.0
    xh = xh_ss / SUPERSAMPLE
    line_y = (baselines / SUPERSAMPLE) - xh / 2
    box = (
        margin_ss / SUPERSAMPLE,
        float(line_y[0] - xh * 1.5),
        (margin_ss + max(widths)) / SUPERSAMPLE,
        float(line_y[-1] + xh * 1.5),
    )
    return PrintedPage(
        lines=list(lines),
        font=face.name,
        coverage=coverage,
        texel_m=float(texel_m),
        xheight_tex=float(xh),
        line_y=line_y.astype(np.float64),
        char_x=char_x,
        text_box=box,
        glyph_boxes=glyph_boxes,
    )


def _glyph_boxes(
    line: str, font: ImageFont.FreeTypeFont, edges: np.ndarray, x0_ss: float, baseline_ss: float
) -> list[tuple[str, float, float, float, float]]:
    """Ink extent of every visible character of a line, in texels (spaces have none)."""
    boxes = []
    for k, ch in enumerate(line):
        left, top, right, bottom = font.getbbox(ch, anchor="ls")
        if right <= left or bottom <= top:
            continue
        x = x0_ss + float(edges[k])
        boxes.append((ch, (x + left) / SUPERSAMPLE, (baseline_ss + top) / SUPERSAMPLE,
                      (x + right) / SUPERSAMPLE, (baseline_ss + bottom) / SUPERSAMPLE))
    return boxes


def reflectance(
    page: PrintedPage, *, paper: float = 0.85, contrast: float = 0.88, blur_tex: float = 0.0
) -> np.ndarray:
    """Paper reflectance image: ``paper`` where blank, ``paper * (1 - contrast)`` under full ink.

    ``blur_tex`` (Gaussian sigma in texels) models print and focus blur.
    """

    cov = page.coverage
    if blur_tex > 0.05:
        cov = cv2.GaussianBlur(cov, (0, 0), blur_tex)
    return (paper * (1.0 - contrast * cov)).astype(np.float32)
