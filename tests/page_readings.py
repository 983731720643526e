"""Synthetic reading passes over rendered text: the frames a reader's glasses would send
(import as ``from page_readings import ...``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from darkread.cloud.ocr.base import OcrLine, OcrResult
from darkread.proto.messages import Frame, pack_mask

LINES = ["the quick brown fox jumps over", "the lazy dog while reading in", "the dark with an event camera"]
PAGE_IN_SENSOR = (300, 200)  # page top-left in sensor pixels (x, y)


def render_page(lines: list[str], x_height_px: int = 10) -> tuple[np.ndarray, list[tuple[int, int, float]]]:
    """Ink mask of the lines, and each line's (x start, x end, y of the x-height centre)."""
    size = 8
    font = ImageFont.load_default(size=size)
    while font.getbbox("x")[3] - font.getbbox("x")[1] < x_height_px:
        size += 1
        font = ImageFont.load_default(size=size)
    pitch = int(x_height_px * 3.2)
    width = max(font.getbbox(line)[2] for line in lines) + 80
    image = Image.new("L", (width, pitch * len(lines) + 80), 255)
    draw = ImageDraw.Draw(image)
    centres = []
    for i, line in enumerate(lines):
        y = 40 + i * pitch
        draw.text((40, y), line, font=font, fill=0)
        box = font.getbbox(line)
        centres.append((40, 40 + box[2], y + (box[1] + box[3]) / 2))
    return (np.asarray(image) < 128).astype(np.uint8), centres


def reading_frames(seed: int = 0, lines: list[str] = LINES, first_seq: int = 0, t0_us: int = 0) -> list[Frame]:
    """A reader's gaze walks each line in ~45 px steps (two frames per fixation, 3 px gaze noise);
    each frame is the 100 x 200 window around the gaze, cut from the sensor image of the page.
    Frames are 40 ms apart from ``t0_us``, numbered from ``first_seq``."""
    page, centres = render_page(lines)
    sensor = np.zeros((720, 1280), np.uint8)
    sx, sy = PAGE_IN_SENSOR
    sensor[sy : sy + page.shape[0], sx : sx + page.shape[1]] = page
    rng = np.random.default_rng(seed)
    frames: list[Frame] = []
    for x_start, x_end, y_centre in centres:
        for gaze_x in np.arange(x_start + 20, x_end, 45):
            for _ in range(2):
                u, v = sx + gaze_x + rng.normal(0, 3), sy + y_centre + rng.normal(0, 3)
                x0, y0 = int(round(u)) - 100, int(round(v)) - 50
                shape, bits = pack_mask(sensor[y0 : y0 + 100, x0 : x0 + 200])
                seq = first_seq + len(frames)
                t_us = t0_us + 40_000 * len(frames)
                frames.append(Frame(seq, seq, t_us, (x0, y0), (float(u), float(v)), (0.0, 0.0), 1600, shape, bits))
    return frames


@dataclass
class CountingOcr:
    """An OCR engine for tests of what is read when: reads a line image as its ink count, and counts the calls."""

    name: str = "counting"
    calls: list[tuple[int, int]] = field(default_factory=list)

    def read(self, image: np.ndarray) -> OcrResult:
        self.calls.append(image.shape)
        text = f"ink {(image < 128).sum()}"
        return OcrResult(text, [OcrLine(text, (0, 0, image.shape[1], image.shape[0]), 1.0)])

    def ready(self) -> bool:
        return True
