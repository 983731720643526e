from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from darkread.edge.fovea import foveate_along_gaze
from darkread.edge.io.evt3_encode import encode_evt3
from darkread.lab.eval.bandwidth import (
    Bandwidth,
    frame_message_bytes,
    image_sizes,
    measure_bandwidth,
    page_message_bytes,
)
from darkread.proto.messages import Frame, encode, pack_mask


def _inside(events: np.ndarray, x0: int, y0: int) -> np.ndarray:
    x, y = events["x"].astype(int), events["y"].astype(int)
    return events[(x >= x0) & (x < x0 + 200) & (y >= y0) & (y < y0 + 100)]


def test_image_sizes_png_is_lossless_and_jpeg_shrinks_with_quality() -> None:
    rng = np.random.default_rng(0)
    image = np.clip(rng.normal(128, 20, (64, 96, 3)), 0, 255).astype(np.uint8)
    sizes = image_sizes(image)
    assert sizes["raw"] == 64 * 96 * 3
    ok, png = cv2.imencode(".png", image[..., ::-1])
    assert ok and sizes["png"] == png.size
    assert np.array_equal(cv2.imdecode(png, cv2.IMREAD_COLOR)[..., ::-1], image)
    jpeg = [sizes[f"jpeg{q}"] for q in (100, 80, 60, 40, 20)]
    assert jpeg == sorted(jpeg, reverse=True) and jpeg[0] > jpeg[-1]


def test_frame_message_size_does_not_depend_on_the_mask() -> None:
    rng = np.random.default_rng(1)
    shape, bits = pack_mask(rng.integers(0, 2, (100, 200), dtype=np.uint8))
    busy = Frame(seq=2**31, frame_id=2**31, t_us=2**40, origin=(1080, 620), gaze_px=(640.5, 360.5),
                 gaze_rad=(0.1, -0.1), events_used=1600, shape=shape, bits=bits)
    assert frame_message_bytes() == len(encode(busy))
    assert 2500 < frame_message_bytes() < 2500 + 200  # 100 x 200 bits plus a small header


def test_page_message_carries_one_bit_per_pixel() -> None:
    size = page_message_bytes(np.ones((300, 800), dtype=np.uint8), enc="bits")  # protocol version 1
    assert 300 * 800 // 8 < size < 300 * 800 // 8 + 100


def test_the_page_goes_as_a_one_bit_png_far_below_its_bits() -> None:
    page = np.zeros((300, 800), np.uint8)
    page[50:60, 20:780:7] = 1  # strokes of a line of text
    page[100:110, 20:600:5] = 1
    assert page_message_bytes(page) < page_message_bytes(page, enc="bits") / 10


def test_foveation_keeps_the_events_in_each_events_own_window(tiny_events: np.ndarray) -> None:
    events = tiny_events
    half = len(events) // 2
    split_t = int(events["t"][half])

    def gaze(t_us: np.ndarray) -> np.ndarray:  # gaze jumps from one point to another mid-way
        return np.where((np.asarray(t_us) < split_t)[:, None], [[300.0, 200.0]], [[900.0, 500.0]])

    kept = foveate_along_gaze(events, gaze, (1280, 720))
    first, second = events["t"] < split_t, events["t"] >= split_t
    # the gaze is sampled per millisecond: events of the millisecond holding the jump may use either window
    ms = events["t"] // 1000 == split_t // 1000
    lo = len(_inside(events[first & ~ms], 200, 150)) + len(_inside(events[second & ~ms], 800, 450))
    assert lo <= len(kept) <= lo + int(ms.sum())
    assert len(kept) > 0
    no_gaze = foveate_along_gaze(events, lambda t: np.full((len(t), 2), np.nan), (1280, 720))
    assert len(no_gaze) == 0


def test_measure_bandwidth_on_a_tiny_recording(tiny_recording: Path, tiny_events: np.ndarray) -> None:
    events = tiny_events
    x0, y0 = 640 - 100, 360 - 50  # straight-ahead gaze lands on the principal point (640, 360)
    expected = _inside(events, x0, y0)
    rgb = np.full((40, 60, 3), 200, dtype=np.uint8)
    page = np.zeros((50, 120), dtype=np.uint8)
    bw = measure_bandwidth(tiny_recording, rgb, page_ink=page)

    raw = (tiny_recording / "events.raw").read_bytes()
    header_len = raw.index(b"% end\n") + len(b"% end\n")
    assert bw.events == len(events)
    assert bw.evt3_bytes == len(raw) - header_len
    assert bw.events_foveated == len(expected)
    assert bw.foveated_evt3_bytes == len(encode_evt3(expected))
    assert bw.frames == math.ceil(len(expected) / 1600) and not bw.frames_measured
    assert bw.frame_stream_bytes == bw.frames * frame_message_bytes()
    assert bw.page_bytes == page_message_bytes(page)
    assert bw.duration_s == 0.05  # meta.json
    assert bw.rgb["raw"] == 40 * 60 * 3
    assert bw.foveation_removed == pytest.approx(1 - len(expected) / len(events))


def test_measured_frame_figures_are_used_as_given(tiny_recording: Path) -> None:
    bw = measure_bandwidth(tiny_recording, np.zeros((8, 8, 3), dtype=np.uint8), frames=7, frame_stream_bytes=12345)
    assert (bw.frames, bw.frame_stream_bytes, bw.frames_measured, bw.page_bytes) == (7, 12345, True, 0)


def test_ratios_against_the_rgb_image() -> None:
    bw = Bandwidth(recording="r", duration_s=2.0, rgb={"raw": 3_000_000, "png": 2_000_000, "jpeg80": 400_000},
                   events=1000, evt3_bytes=4000, events_foveated=20, foveated_evt3_bytes=100, frames=40,
                   frame_stream_bytes=200_000, page_bytes=1_000)
    ratios = bw.ratios()
    assert ratios["foveation_removed"] == pytest.approx(0.98)
    assert ratios["rgb_png_vs_frames_per_s"] == pytest.approx(2_000_000 / 100_000)
    assert ratios["rgb_png_vs_page"] == pytest.approx(2000)
    assert ratios["rgb_jpeg80_vs_page"] == pytest.approx(400)
    assert Bandwidth.from_json(bw.to_json()) == bw
