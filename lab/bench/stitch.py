"""Stitching: time per frame and ink F1 against the true page, next to naive placement (every frame
at its sensor position, no registration) measured on the same synthetic readings.

The readings come from the stitcher tests' generator (``tests/stitch/reading_factory.py``: a rendered
page, a reading scanpath with gaze noise, head drift/tremor/roll, speckle, missing strokes and
dropped frames), so this benchmark needs a source checkout.
"""

from __future__ import annotations

import importlib.util
import re
import sys
import time
from pathlib import Path
from types import ModuleType

import cv2
import jiwer
import numpy as np

from darkread.core.image_codec import decode_image
from darkread.lab.bench import BenchContext, Figure
from darkread.stitch import naive_page, stitch_page

_SCAN = Path(__file__).resolve().parents[2] / "tests" / "stitch" / "reading_factory.py"


def load_scan() -> ModuleType | None:
    """The synthetic reading generator, or None outside a source checkout."""
    if not _SCAN.is_file():
        return None
    if "reading_factory" in sys.modules:
        return sys.modules["reading_factory"]
    spec = importlib.util.spec_from_file_location("reading_factory", _SCAN)
    if spec is None or spec.loader is None:
        return None
    module = importlib.util.module_from_spec(spec)
    sys.modules["reading_factory"] = module
    spec.loader.exec_module(module)
    return module


def _ocr_reader():
    """rapidocr (the cloud extra) on one thread, or None when it is not installed."""
    try:
        from rapidocr import RapidOCR
    except ImportError:
        return None
    params = {
        "Global.use_cls": False,
        "Global.log_level": "error",
        "EngineConfig.onnxruntime.intra_op_num_threads": 1,
        "EngineConfig.onnxruntime.inter_op_num_threads": 1,
    }
    engine = RapidOCR(params=params)

    def read(png: bytes) -> str:

        result = engine(decode_image(png, colour=True))
        return re.sub(r"\s+", " ", " ".join(result.txts or ())).strip()

    return read


def run(ctx: BenchContext) -> list[Figure]:


    scan = load_scan()
    if scan is None:
        ctx.notes.append(f"stitch: skipped, the synthetic reading generator {_SCAN} is not here")
        return []
    page = scan.render_page(scan.PARAGRAPH.split(". ")[0] + ".") if ctx.smoke else scan.render_page()
    seeds = [0] if ctx.quick or ctx.smoke else [0, 1, 2]
    ours_s = naive_s = 0.0
    frames_total = 0
    f1: dict[str, list[float]] = {"ours": [], "naive": [], "ours_tol": [], "naive_tol": []}
    cer: dict[str, list[float]] = {"ours": [], "naive": []}
    read = _ocr_reader()
    if read is None:
        ctx.notes.append("stitch: rapidocr not installed, no OCR figure")
    truth = " ".join(page.text_lines)
    for seed in seeds:
        reading = scan.simulate_reading(page, seed=seed)
        frames_total += len(reading.frames)
        started = time.perf_counter()
        stitched = stitch_page(reading.frames)
        ours_s += time.perf_counter() - started
        started = time.perf_counter()
        naive = naive_page(reading.frames)
        naive_s += time.perf_counter() - started
        f1["ours"].append(scan.ink_f1_aligned(stitched.image, page.mask)[0])
        f1["naive"].append(scan.ink_f1_aligned(naive.image, page.mask)[0])
        f1["ours_tol"].append(scan.ink_f1_aligned(stitched.image, page.mask, tolerance_px=1)[0])
        f1["naive_tol"].append(scan.ink_f1_aligned(naive.image, page.mask, tolerance_px=1)[0])
        if read is not None:
            cer["ours"].append(jiwer.cer(truth, read(stitched.to_png_bytes())))
            cer["naive"].append(jiwer.cer(truth, read(naive.to_png_bytes())))
    mean = {k: sum(v) / len(v) for k, v in f1.items()}
    ours_ms, naive_ms = 1000 * ours_s / frames_total, 1000 * naive_s / frames_total
    where = f"{len(seeds)} reading{'s' if len(seeds) > 1 else ''}, {frames_total} frames of 100x200"
    figures = [
        Figure(
            "stitch_ms_per_frame",
            ours_ms,
            f"stitch: ms per frame ({where})",
            f"naive placement: {naive_ms:.3f} ms/frame",
            "<= 10 ms/frame (100 frames/s on one core)",
        ),
        Figure(
            "stitch_ink_f1",
            mean["ours"],
            "stitch: ink F1 vs true page (exact pixels, best shift/roll)",
            f"naive placement: {mean['naive']:.3f}",
            ">= 0.75",
        ),
        Figure(
            "stitch_ink_f1_tol1px",
            mean["ours_tol"],
            "stitch: ink F1 vs true page (1 px tolerance)",
            f"naive placement: {mean['naive_tol']:.3f}",
            ">= 0.97",
        ),
    ]
    if cer["ours"]:
        figures.append(
            Figure(
                "stitch_ocr_cer",
                sum(cer["ours"]) / len(cer["ours"]),
                "stitch: rapidocr CER of the stitched page",
                f"naive placement: {sum(cer['naive']) / len(cer['naive']):.3f}",
                "< 0.05",
            )
        )
    return figures


def write_example(path: Path, seed: int = 0) -> Path:
    """``docs/stitch_example.png``: the true page, naive placement and the stitched page, stacked."""


    scan = load_scan()
    if scan is None:
        raise FileNotFoundError(f"the synthetic reading generator {_SCAN} is needed for the example")
    page = scan.render_page()
    reading = scan.simulate_reading(page, seed=seed)
    stitched = stitch_page(reading.frames)
    naive = naive_page(reading.frames)
    exact_ours, (dx, dy) = scan.ink_f1_aligned(stitched.image, page.mask)
    exact_naive, _ = scan.ink_f1_aligned(naive.image, page.mask)
    f1_ours, _ = scan.ink_f1_aligned(stitched.image, page.mask, tolerance_px=1)
    f1_naive, _ = scan.ink_f1_aligned(naive.image, page.mask, tolerance_px=1)
    # the truth cut to the stitched page's extent, so the three panels line up
    h, w = stitched.image.shape
    truth = np.pad(page.mask, ((h, h), (w, w)))[dy + h : dy + 2 * h, dx + w : dx + 2 * w]
    panels = [
        ("truth: rendered page", truth),
        (
            f"naive: frames pasted at their sensor position (ink F1 {exact_naive:.2f}; {f1_naive:.2f} within 1 px)",
            naive.image,
        ),
        (
            (
                f"stitched: {len(stitched.lines)} line boxes, {stitched.frames_used} frames "
                f"(ink F1 {exact_ours:.2f}; {f1_ours:.2f} within 1 px)"
            ),
            stitched.image,
        ),
    ]
    width = max(img.shape[1] for _, img in panels) + 20
    rows = []
    for title, img in panels:
        grey = np.full((img.shape[0] + 40, width), 255, np.uint8)
        grey[30 : 30 + img.shape[0], 10 : 10 + img.shape[1]] = np.where(img > 0, 0, 255)
        cv2.putText(grey, title, (10, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 0, 1, cv2.LINE_AA)
        rows.append(grey)
    canvas = cv2.cvtColor(np.vstack(rows), cv2.COLOR_GRAY2BGR)
    for x0, y0, x1, y1 in stitched.lines:  # line boxes of the stitched page, in blue
        top = rows[0].shape[0] + rows[1].shape[0] + 30
        cv2.rectangle(canvas, (10 + x0 - 2, top + y0 - 1), (10 + x1 + 1, top + y1), (255, 120, 0), 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), canvas):
        raise OSError(f"cannot write {path}")
    return path


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="Write the stitching example figure (truth, naive, stitched).")
    parser.add_argument("--example", type=Path, default=Path("docs/stitch_example.png"), help="output PNG")
    parser.add_argument("--seed", type=int, default=0, help="synthetic reading seed")
    print(write_example(parser.parse_args().example, parser.parse_args().seed))
