"""One frame record from the U-Net to the stitcher: the edge's result, the wire message and the store's row carry it."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.cloud.store import StoredFrame
from darkread.core.frame_record import FrameRecord
from darkread.edge.frame import FrameResult
from darkread.proto.messages import Frame, decode, encode


def _mask() -> np.ndarray:
    return np.random.default_rng(1).integers(0, 2, (100, 200), dtype=np.uint8)


def test_the_record_normalises_its_fields() -> None:
    record = FrameRecord(3, 10, np.full((8, 9), 255, np.uint8), (np.int64(4), 5.0), (1, np.float32(2.5)))
    assert record.mask.max() == 1 and record.mask.dtype == np.uint8
    assert record.origin == (4, 5) and type(record.origin[0]) is int
    assert record.gaze_px == (1.0, 2.5) and type(record.gaze_px[0]) is float
    with pytest.raises(ValueError, match="2-D"):
        FrameRecord(1, 0, np.zeros((0, 4), np.uint8), (0, 0), (0.0, 0.0))
    assert FrameRecord(1, 0, np.ones((8, 9), np.uint8), (0, 0), (0.0, 0.0), light_lux=np.float32(6.5)).light_lux == 6.5
    for dark in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="light_lux"):
            FrameRecord(1, 0, np.ones((8, 9), np.uint8), (0, 0), (0.0, 0.0), light_lux=dark)


def test_the_wire_carries_the_record_unchanged() -> None:
    record = FrameRecord(7, 123_456, _mask(), (540, 310), (640.25, 360.5))
    message = decode(encode(Frame.of(record, seq=9, gaze_rad=(0.1, -0.2), events_used=1600)), max_bytes=1 << 20)
    assert isinstance(message, Frame) and (message.seq, message.gaze_rad, message.events_used) == (9, (0.1, -0.2), 1600)
    back = message.record()
    assert (back.frame_id, back.t_us, back.origin, back.gaze_px) == (7, 123_456, (540, 310), (640.25, 360.5))
    np.testing.assert_array_equal(back.mask, record.mask)


def test_the_edge_result_and_the_stored_frame_are_frame_records() -> None:
    result = FrameResult(1, 2, _mask(), (3, 4), (5.0, 6.0), gaze_rad=(0.5, 0.25), events_used=1600, inference_ms=1.5)
    stored = StoredFrame(1, 2, result.mask, (3, 4), (5.0, 6.0), seq=11)
    assert isinstance(result, FrameRecord) and isinstance(stored, FrameRecord)
    message = result.to_message()
    assert (message.gaze_rad, message.events_used, message.seq) == ((0.5, 0.25), 1600, 0)
    np.testing.assert_array_equal(message.mask(), stored.mask)



def test_a_fused_view_carries_its_probability_and_frame_count() -> None:
    levels = np.array([[0, 1, 2, 3]], np.uint8)
    view = FrameRecord(1, 2, (levels >= 2).astype(np.uint8), (0, 0), (0.0, 0.0), levels=levels, n_levels=4, frames=5)
    np.testing.assert_allclose(view.ink_probability(), [[0.0, 1 / 3, 2 / 3, 1.0]], rtol=1e-6)
    assert view.frames == 5
    binary = FrameRecord(1, 2, (levels >= 2).astype(np.uint8), (0, 0), (0.0, 0.0))
    np.testing.assert_array_equal(binary.ink_probability(), [[0.0, 0.0, 1.0, 1.0]])
    assert binary.frames == 1 and binary.levels is None
    with pytest.raises(ValueError, match="levels must be integers 0 .. 3"):
        FrameRecord(1, 2, binary.mask, (0, 0), (0.0, 0.0), levels=levels + 1, n_levels=4)
    with pytest.raises(ValueError, match="shape"):
        FrameRecord(1, 2, binary.mask, (0, 0), (0.0, 0.0), levels=levels[:, :2], n_levels=4)
    with pytest.raises(ValueError, match="frames"):
        FrameRecord(1, 2, binary.mask, (0, 0), (0.0, 0.0), frames=0)
