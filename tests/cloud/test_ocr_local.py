"""Local OCR engines, the reading order, and backend selection."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from PIL import Image, ImageDraw, ImageFont

from darkread.cloud.errors import OcrError
from darkread.cloud.ocr import create_backend
from darkread.cloud.ocr.base import OcrLine, reading_order
from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.cloud.ocr.tesseract import TesseractBackend, lines_from_words
from darkread.cloud.settings import Settings

SENTENCE = "the quick brown fox jumps over the lazy dog"


def render_line(text: str, x_height_px: int = 10) -> np.ndarray:
    """Clean binary black-on-white text with the requested lower-case height."""
    size = 8
    font = ImageFont.load_default(size=size)
    while font.getbbox("x")[3] - font.getbbox("x")[1] < x_height_px:
        size += 1
        font = ImageFont.load_default(size=size)
    left, top, right, bottom = font.getbbox(text)
    image = Image.new("L", (right - left + 40, bottom - top + 40), 255)
    ImageDraw.Draw(image).text((20 - left, 20 - top), text, font=font, fill=0)
    return np.where(np.asarray(image) < 128, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def rapid() -> RapidOcrBackend:
    return RapidOcrBackend()


def test_rapidocr_reads_a_clean_line_at_x_height_10(rapid: RapidOcrBackend) -> None:
    image = render_line(SENTENCE, 10)
    assert rapid.ready()
    result = rapid.read(image)
    assert " ".join(result.text.split()) == SENTENCE
    assert len(result.lines) == 1
    box = result.lines[0].box
    assert box is not None
    x0, y0, x1, y1 = box
    assert x0 <= 25 and x1 >= image.shape[1] - 25 and y0 <= 22 and y1 >= image.shape[0] - 22
    assert result.lines[0].confidence is not None and result.lines[0].confidence > 0.8


def test_ready_loads_the_models_so_the_first_question_does_not() -> None:
    """rapidocr 3 loads its detection and recognition models on first use; ``ready`` (the
    service's warm-up and /readyz) must do it, or the first ask pays a second or more for it."""
    backend = RapidOcrBackend(engines=2)
    assert backend.ready()
    with backend._engine() as first, backend._engine() as second:
        assert first is not second  # both made by ready, none waits for the other
        assert all(e.text_det is not None and e.text_rec is not None for e in (first, second))


def test_engines_read_in_parallel_threads_and_each_right() -> None:
    import threading

    backend = RapidOcrBackend(engines=2)
    lines = {text: render_line(text, 10) for text in ("reading in the dark", "with event cameras")}
    got: dict[str, list[str]] = {text: [] for text in lines}
    barrier = threading.Barrier(2)

    def read(text: str) -> None:
        barrier.wait()
        for _ in range(3):
            got[text].append(" ".join(backend.read(lines[text]).text.split()))

    threads = [threading.Thread(target=read, args=(text,)) for text in lines]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert got == {text: [text] * 3 for text in lines}
    assert backend._made == 2


def test_the_service_makes_one_engine_per_ocr_thread() -> None:
    backend = create_backend(Settings(_env_file=None, ocr_threads=3, ocr_lexicon=False))
    assert isinstance(backend, RapidOcrBackend) and backend.engines == 3
    with pytest.raises(ValueError, match="at least 1"):
        RapidOcrBackend(engines=0)


def test_rapidocr_reads_two_lines_in_order(rapid: RapidOcrBackend) -> None:
    first, second = render_line("reading in the dark", 10), render_line("with event cameras", 10)
    width = max(first.shape[1], second.shape[1])
    page = np.full((first.shape[0] + second.shape[0], width), 255, np.uint8)
    page[: first.shape[0], : first.shape[1]] = first
    page[first.shape[0] :, : second.shape[1]] = second
    assert rapid.read(page).text.split("\n") == ["reading in the dark", "with event cameras"]


def test_blank_page_reads_as_empty(rapid: RapidOcrBackend) -> None:
    result = rapid.read(np.full((64, 200), 255, np.uint8))
    assert result.text == "" and result.lines == []


@pytest.mark.parametrize("bad", [np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.float32), np.zeros((0, 5), np.uint8)])
def test_wrong_images_are_refused(rapid: RapidOcrBackend, bad: np.ndarray) -> None:
    with pytest.raises(OcrError, match="2-D uint8"):
        rapid.read(bad)


def test_tesseract_reads_a_clean_line_when_installed() -> None:
    backend = TesseractBackend()
    if not backend.ready():
        pytest.skip("Tesseract is not installed (make system-deps; pip install pytesseract)")
    assert " ".join(backend.read(render_line(SENTENCE, 10)).text.split()) == SENTENCE


def test_tesseract_missing_gives_an_actionable_error(monkeypatch: pytest.MonkeyPatch) -> None:
    backend = TesseractBackend()
    monkeypatch.setattr(backend, "_tesserocr_api", lambda: None)
    monkeypatch.setitem(sys.modules, "pytesseract", None)  # as if not installed
    with pytest.raises(OcrError, match="apt-get install tesseract-ocr"):
        backend.read(render_line("abc"))
    assert not backend.ready()


def test_tesseract_word_table_becomes_lines() -> None:
    # What pytesseract.image_to_data(..., output_type=DICT) returns: page, block, paragraph,
    # line and word rows; only level 5 rows carry words; conf -1 for non-word rows.
    rows = [
        (1, 1, 0, 0, 0, 0, 0, 0, 300, 100, -1, ""),
        (4, 1, 1, 1, 1, 0, 10, 10, 200, 12, -1, ""),
        (5, 1, 1, 1, 1, 1, 10, 10, 50, 12, 96.0, "second"),
        (5, 1, 1, 1, 1, 2, 70, 10, 40, 12, 90.0, "row"),
        (5, 1, 1, 1, 2, 1, 12, 40, 45, 12, 95.0, "third"),
        (5, 1, 1, 1, 2, 2, 60, 40, 5, 12, 95.0, " "),
    ]
    keys = ("level", "page_num", "block_num", "par_num", "line_num", "word_num", "left", "top", "width", "height", "conf", "text")
    data = {key: [row[i] for row in rows] for i, key in enumerate(keys)}
    lines = lines_from_words(data)
    assert [line.text for line in lines] == ["second row", "third"]
    assert lines[0].box == (10, 10, 110, 22) and lines[0].confidence == pytest.approx(0.93)


def test_reading_order_is_top_to_bottom_then_left_to_right() -> None:
    lines = [
        OcrLine("c", (10, 40, 50, 52)),
        OcrLine("b", (120, 11, 160, 23)),  # same row as "a", slightly lower
        OcrLine("a", (10, 10, 100, 22)),
        OcrLine("d", (60, 42, 90, 53)),
    ]
    assert [line.text for line in reading_order(lines)] == ["a", "b", "c", "d"]


def test_backend_selection(tmp_path: object) -> None:
    assert create_backend(Settings(_env_file=None, ocr_backend="local")).name == "rapidocr+lexicon"
    assert create_backend(Settings(_env_file=None, ocr_backend="tesseract")).name == "tesseract+lexicon"
    raw = Settings(_env_file=None, ocr_backend="local", ocr_lexicon=False)
    assert create_backend(raw).name == "rapidocr"
    with pytest.raises(OcrError, match="GOOGLE_API_KEY"):
        create_backend(Settings(_env_file=None, ocr_backend="google"))
    openai = create_backend(Settings(_env_file=None, ocr_backend="openai", openai_base_url="http://127.0.0.1:9/v1"))
    assert openai.name == "openai" and not openai.ready()
    openai.close()  # type: ignore[attr-defined]  # the OpenAI engine has close(), the OcrBackend protocol does not


def _tilted(text: str, x0: float, y0: float, length: float, slope: float = 0.12, height: float = 14.0) -> OcrLine:
    """A text line starting at (x0, y0) (top-left), running ``length`` px along a tilted baseline."""
    quad = ((x0, y0), (x0 + length, y0 + slope * length), (x0 + length, y0 + slope * length + height), (x0, y0 + height))
    xs, ys = [p[0] for p in quad], [p[1] for p in quad]
    return OcrLine(text, (int(min(xs)), int(min(ys)), int(max(xs)) + 1, int(max(ys)) + 1), 0.9, quad)


def test_reading_order_follows_a_tilted_page_line_by_line() -> None:
    lines = [
        _tilted("liberty, Lords and Commons,", 45, 45, 290),  # long line: its upright box reaches far down
        _tilted("which your own", 45, 72, 140),
        _tilted("valorous and", 195, 72 + 0.12 * 150, 100),  # the same row, detected as a second piece
        _tilted("happy counsels have", 45, 99, 200),
        _tilted("purchased us, liberty which", 45, 126, 270),
    ]
    expected = ["liberty, Lords and Commons,", "which your own", "valorous and", "happy counsels have",
                "purchased us, liberty which"]
    assert [line.text for line in reading_order(lines[::-1])] == expected
    upright = [OcrLine(line.text, line.box, line.confidence) for line in lines]  # the same boxes without their tilt
    assert [line.text for line in reading_order(upright)] != expected  # why the rotated boxes matter
