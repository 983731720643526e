"""The one bit layout of ink masks: whole masks (wire, store) and row-packed batches (training shards)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from darkread.core.mask_bits import pack_bits, pack_rows, packed_length, unpack_bits, unpack_rows

masks = hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=40), elements=st.integers(0, 3))
batches = hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=4, min_side=1, max_side=19), elements=st.integers(0, 1))


@given(masks)
def test_whole_masks_round_trip_with_any_nonzero_value_as_ink(mask: np.ndarray) -> None:
    bits = pack_bits(mask)
    assert len(bits) == packed_length(mask.shape)
    out = unpack_bits(mask.shape, bits)
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, (mask != 0).astype(np.uint8))


@given(batches)
def test_row_packed_batches_round_trip(masks: np.ndarray) -> None:
    packed = pack_rows(masks)
    assert packed.shape == (*masks.shape[:-1], (masks.shape[-1] + 7) // 8)
    np.testing.assert_array_equal(unpack_rows(packed, masks.shape[-1]), masks)


def test_the_layout_is_msb_first_row_major() -> None:
    mask = np.zeros((2, 5), np.uint8)
    mask[0, 0] = mask[1, 4] = 1  # pixels 0 and 9
    assert pack_bits(mask) == bytes([0b1000_0000, 0b0100_0000])
    assert pack_rows(mask).tolist() == [[0b1000_0000], [0b0000_1000]]


def test_a_window_packs_the_same_both_ways_when_its_width_is_whole_bytes() -> None:
    mask = np.random.default_rng(0).integers(0, 2, (100, 200), dtype=np.uint8)
    assert pack_rows(mask).tobytes() == pack_bits(mask)
