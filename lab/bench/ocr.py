"""OCR: milliseconds per page and character error rate for each local engine that is installed,
next to rapidocr with its stock detector settings (short side upscaled to 736 px) on the same
page in the same run.

The page is a rendered 9-line paragraph, binary black on white, x-height 10 px (what the
reconstructor delivers for printed text at reading distance) and 7 px (near the breakdown).
"""

from __future__ import annotations

import re
import textwrap
import time
import unicodedata
from typing import TYPE_CHECKING

import jiwer
import numpy as np

from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.cloud.ocr.tesseract import TesseractBackend
from darkread.lab.bench import BenchContext, Figure

if TYPE_CHECKING:
    from darkread.cloud.ocr.base import OcrBackend

PARAGRAPH = (
    "Reading in the dark is hard for cameras and easy for events. A foveated window follows the gaze "
    "along each line of text, and every small binary frame shows a few words. The stitcher places these "
    "frames onto one page, line after line, so that a text recogniser can read the whole page back. "
    "Head motion moves the page in the sensor, so frames are registered against what was already seen."
)


def render_page(x_height_px: int, width_chars: int = 52, text: str = PARAGRAPH) -> tuple[np.ndarray, str]:
    from PIL import Image, ImageDraw, ImageFont

    size = 6
    font = ImageFont.load_default(size=size)
    while font.getbbox("x")[3] - font.getbbox("x")[1] < x_height_px:
        size += 1
        font = ImageFont.load_default(size=size)
    lines = textwrap.wrap(text, width_chars)
    pitch = int(x_height_px * 3)
    width = int(max(font.getbbox(line)[2] for line in lines)) + 40
    image = Image.new("L", (width, pitch * len(lines) + 40), 255)
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((20, 20 + i * pitch), line, font=font, fill=0)
    return np.where(np.asarray(image) < 128, 0, 255).astype(np.uint8), " ".join(lines)


def normalise(text: str) -> str:
    return re.sub(r"\s+", " ", unicodedata.normalize("NFKC", text)).strip()


def cer(reference: str, hypothesis: str) -> float:

    return float(jiwer.cer(normalise(reference), normalise(hypothesis) or " "))


def _time_engine(engine: OcrBackend, image: np.ndarray, repeats: int) -> tuple[float, str]:
    """Median ms of ``repeats`` reads after a warm-up read (``repeats`` 0: the warm-up read itself)."""
    started = time.perf_counter()
    text = engine.read(image).text  # warm-up (model load)
    times = [time.perf_counter() - started] if repeats == 0 else []
    for _ in range(repeats):
        started = time.perf_counter()
        text = engine.read(image).text
        times.append(time.perf_counter() - started)
    return float(np.median(times)) * 1000, text


def run(ctx: BenchContext) -> list[Figure]:

    repeats = ctx.runs(5, 2, 0)
    text = PARAGRAPH.split(". ")[0] + "." if ctx.smoke else PARAGRAPH
    stock = RapidOcrBackend(params={"Det.limit_type": "min", "Det.limit_side_len": 736})
    engines: dict[str, OcrBackend] = {"rapidocr": RapidOcrBackend(), "tesseract": TesseractBackend()}
    for name in [name for name, engine in engines.items() if not engine.ready()]:
        ctx.notes.append(f"ocr: {name} is not installed, skipped")
        del engines[name]
    figures: list[Figure] = []
    for x_height in (10, 7):
        page, truth = render_page(x_height, text=text)
        stock_ms, stock_text = _time_engine(stock, page, repeats)
        reference = f"rapidocr stock det: {stock_ms:.0f} ms, CER {cer(truth, stock_text):.3f}"
        for name, engine in engines.items():
            ms, text = _time_engine(engine, page, repeats)
            shape = f"{page.shape[1]}x{page.shape[0]} px"
            figures.append(
                Figure(
                    key=f"ocr_{name}_ms_per_page_xh{x_height}",
                    value=ms,
                    label=f"OCR {name}, x-height {x_height} px, {shape} [ms/page]",
                    reference=reference,
                    goal="<= 1000 ms",
                )
            )
            figures.append(
                Figure(
                    key=f"ocr_{name}_cer_xh{x_height}",
                    value=cer(truth, text),
                    label=f"OCR {name}, x-height {x_height} px [CER]",
                    reference=reference,
                    goal="<= 0.01" if x_height >= 10 else "<= 0.03",
                )
            )
    return figures
