"""Paging and line reading without a server: pure functions of the frames they are given."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from page_readings import LINES, CountingOcr, reading_frames

from darkread.cloud.live import LineReader, Paginator, PagingConfig
from darkread.cloud.live.reading import BORDER_PX
from darkread.cloud.ocr.base import OcrLine, OcrResult
from darkread.cloud.store import StoredFrame
from darkread.cloud.stream import stored_frame
from darkread.stitch.page import text_bands

OTHER_LINES = ["a second page of text comes", "after the first one was read", "by the same pair of glasses"]


def frames(lines: list[str] = LINES, first_seq: int = 0, t0_us: int = 0, seed: int = 0) -> list:
    return [stored_frame(f) for f in reading_frames(seed=seed, lines=lines, first_seq=first_seq, t0_us=t0_us)]


def paginate(records: list, cfg: PagingConfig = PagingConfig(), breaks: tuple[int, ...] = ()) -> Paginator:
    paginator = Paginator(cfg=cfg)
    for record in records:
        if record.seq in breaks:
            paginator.page_break()
        paginator.add(record)
    return paginator


def summary(paginator: Paginator) -> list[tuple[int, str, int, int, int]]:
    return [(p.index, p.started_by, p.first_seq, p.last_seq, p.version) for p in paginator.pages]


def test_the_same_frames_give_the_same_pages() -> None:
    first = frames()
    both = first + frames(OTHER_LINES, first_seq=len(first), t0_us=first[-1].t_us + 200_000, seed=1)
    once, again = paginate(both), paginate(both)
    assert summary(once) == summary(again)
    assert [p.started_by for p in once.pages] == ["first", "lost"]
    np.testing.assert_array_equal(once.render(once.pages[1]).grey, again.render(again.pages[1]).grey)


def test_a_page_break_starts_a_page_and_the_old_one_is_finished() -> None:
    records = frames()
    paginator = paginate(records, breaks=(20,))
    assert [(p.started_by, p.first_seq) for p in paginator.pages] == [("first", 0), ("break", 20)]
    old = paginator.pages[0]
    assert old.finished and old.rendered is not None and old.rendered.last_seq == 19
    assert paginator.render(old) is old.rendered  # a finished page keeps its last render


def test_a_page_that_outgrows_the_pixel_bound_starts_anew() -> None:
    paginator = paginate(frames(), PagingConfig(max_page_pixels=200_000))
    assert len(paginator.pages) > 1 and {p.started_by for p in paginator.pages[1:]} == {"size"}


def test_frames_at_the_same_gaze_within_the_gap_are_skipped() -> None:
    records = frames()
    every = paginate(records)
    thinned = paginate(records, PagingConfig(min_stitch_gap_us=100_000, same_place_px=60))
    assert thinned.skipped > 0 and thinned.current.version < every.current.version


def test_a_version_is_read_once_and_unchanged_lines_are_not_read_again() -> None:
    paginator = paginate(frames())
    page = paginator.render(paginator.current)
    assert page is not None and len(page.bands) == len(LINES)
    ocr = CountingOcr()
    reader = LineReader(ocr)
    first = reader.read(page)
    assert first.lines_read == len(LINES) and len(ocr.calls) == len(LINES)
    assert reader.read(page) is first and len(ocr.calls) == len(LINES)  # the same version: cached
    moved = type(page)(page.index, page.version + 1, page.grey, page.ink, page.bands, page.first_seq, page.last_seq)
    second = reader.read(moved)
    assert second.lines_read == 0 and [ln.text for ln in second.lines] == [ln.text for ln in first.lines]
    assert {ln.read_at_version for ln in second.lines} == {page.version}


def test_a_frame_too_small_to_stitch_is_refused_and_changes_nothing() -> None:
    paginator = Paginator()
    with pytest.raises(ValueError, match="too small"):
        paginator.add(StoredFrame(0, 0, np.ones((4, 4), np.uint8), (0, 0), (0.0, 0.0), seq=0))
    assert paginator.pages == [] and paginator.current is None


@dataclass
class BlindOnCrops:
    """An engine whose detector finds nothing on an image under ``min_height`` px (as a text
    detector on a crop of one small line) and reports each row band of ink with its box otherwise."""

    min_height: int = 60
    name: str = "blind-on-crops"
    shapes: list[tuple[int, int]] = field(default_factory=list)

    def read(self, image: np.ndarray) -> OcrResult:
        self.shapes.append(image.shape)
        if image.shape[0] < self.min_height:
            return OcrResult("", [])
        lines = []
        for top, bottom, _ in text_bands((image < 128).astype(np.uint8)):
            cols = np.flatnonzero((image[top:bottom] < 128).any(axis=0))
            lines.append(OcrLine(f"ink at {top}", (int(cols[0]), top, int(cols[-1]) + 1, bottom), 0.9))
        return OcrResult("\n".join(line.text for line in lines), lines)


def test_lines_a_crop_reads_nothing_are_read_again_in_place_each_keeping_its_own_text() -> None:
    paginator = paginate(frames())
    page = paginator.render(paginator.current)
    assert page is not None and len(page.bands) == len(LINES)
    ocr = BlindOnCrops()
    reading = LineReader(ocr).read(page)
    # three crops (nothing), then one read of the page's size with the three lines in place
    assert len(ocr.shapes) == len(LINES) + 1 and ocr.shapes[-1][0] > page.grey.shape[0]
    assert reading.lines_read == len(LINES) and len(reading.lines) == len(LINES)
    tops = [int(line.text.split()[-1]) - BORDER_PX for line in reading.lines]
    for top, line in zip(tops, reading.lines):  # each text went to the line its box lies in
        assert line.box[1] <= top + 1 and top < line.box[3]
    assert len(set(tops)) == len(LINES)


def test_an_engine_without_boxes_reads_crops_only() -> None:
    paginator = paginate(frames())
    page = paginator.render(paginator.current)
    assert page is not None

    @dataclass
    class NoBoxes:
        name: str = "no-boxes"
        calls: int = 0

        def read(self, image: np.ndarray) -> OcrResult:
            self.calls += 1
            return OcrResult("" if image.shape[0] < 60 else "page text", [OcrLine("" if image.shape[0] < 60 else "page text")])

    ocr = NoBoxes()
    reading = LineReader(ocr).read(page)
    assert ocr.calls == len(LINES) + 1 and reading.text == ""  # the in-place read had no boxes: not used
    # each band read as nothing is an unclear line, not left out
    assert [line.text for line in reading.lines] == [""] * len(LINES)
    assert all(line.judgement is not None and line.judgement.status == "unclear" for line in reading.lines)


def test_only_the_lines_whose_crop_read_nothing_take_the_in_place_text() -> None:
    paginator = paginate(frames())
    page = paginator.render(paginator.current)
    assert page is not None and len(page.bands) == len(LINES)

    @dataclass
    class BlindOnTheMiddleCrop(BlindOnCrops):
        crops: int = 0
        lines_in_place: int = 0

        def read(self, image: np.ndarray) -> OcrResult:
            if image.shape[0] >= self.min_height:  # in place: every changed line, each with its own box
                self.lines_in_place = len(text_bands((image < 128).astype(np.uint8)))
                return super().read(image)
            self.crops += 1
            text = "" if self.crops == 2 else f"crop {self.crops}"
            return OcrResult(text, [OcrLine(text, (0, 0, image.shape[1], image.shape[0]), 0.8)] if text else [])

    ocr = BlindOnTheMiddleCrop()
    reading = LineReader(ocr).read(page)
    texts = [line.text for line in reading.lines]
    assert texts[0] == "crop 1" and texts[2] == "crop 3" and texts[1].startswith("ink at")
    assert len(ocr.shapes) == 1 and ocr.lines_in_place == len(LINES)  # one reading in place, of all three lines


def test_a_page_knows_the_light_the_glasses_measured_while_its_frames_came() -> None:
    """The light is evidence for a page's lines: the geometric mean over the frames that said it
    (a page read while the light went from 5 to 20 lux was read at about 10); None when none did."""
    from dataclasses import replace

    records = frames()
    assert paginate(records).pages[0].motion.light_lux() is None
    lit = [replace(r, light_lux=5.0 if k % 2 else 20.0) if k % 3 else r for k, r in enumerate(records)]
    motion = paginate(lit).pages[0].motion
    assert motion.lit_records == sum(1 for k in range(len(records)) if k % 3)
    assert motion.light_lux() == pytest.approx(10.0, rel=0.1)


def test_a_page_knows_how_much_the_glasses_shed_while_its_frames_came() -> None:
    """The mean shedding level of a page's frames and views (edge.load) is evidence for its lines."""
    from dataclasses import replace

    records = frames()
    kept_up = paginate(records).pages[0].motion
    assert kept_up.shed_level() == 0.0
    starved = paginate([replace(r, shed_level=3 if k % 2 else 1) for k, r in enumerate(records)]).pages[0].motion
    assert starved.records == len(records) and starved.shed_level() == pytest.approx(2.0, abs=0.1)
