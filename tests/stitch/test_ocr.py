"""The stitched page reads back: rapidocr on the stitched synthetic page, CER against the text."""

from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("rapidocr")
pytest.importorskip("onnxruntime")  # rapidocr 3.x brings no inference engine of its own


def _normalise(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


@pytest.mark.slow
def test_ocr_reads_the_stitched_page_back(rendered_page, stitched) -> None:
    import cv2
    import jiwer
    from rapidocr import RapidOCR

    engine = RapidOCR(
        params={
            "Global.use_cls": False,
            "Global.log_level": "error",
            "EngineConfig.onnxruntime.intra_op_num_threads": 1,
            "EngineConfig.onnxruntime.inter_op_num_threads": 1,
        }
    )
    image = cv2.imdecode(np.frombuffer(stitched.to_png_bytes(), np.uint8), cv2.IMREAD_COLOR)
    result = engine(image)
    read = _normalise(" ".join(result.txts or ()))
    truth = _normalise(" ".join(rendered_page.text_lines))
    cer = jiwer.cer(truth, read)
    assert cer < 0.05, f"CER {cer:.3f}: {read!r}"
