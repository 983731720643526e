"""Ink masks as bits, written once: the wire, the cloud's database and the training shards all
store a binary mask as ``np.packbits`` output (MSB first, ink = 1). Pure: numpy only.

Two layouts: a whole mask flattened row-major (``pack_bits``: the wire and the store), and each
row packed on its own along the last axis (``pack_rows``: batches of training targets, which
stay indexable by sample and row).
"""

from __future__ import annotations

import numpy as np


def packed_length(shape: tuple[int, int]) -> int:
    """Bytes of ``pack_bits`` output for a mask of ``shape`` (rows, cols)."""
    return (shape[0] * shape[1] + 7) // 8


def pack_bits(mask: np.ndarray) -> bytes:
    """A mask (nonzero = ink) -> its pixels row-major as bits, MSB first, zero-padded to a byte."""
    return np.packbits(np.asarray(mask) != 0, axis=None).tobytes()


def unpack_bits(shape: tuple[int, int], bits: bytes) -> np.ndarray:
    """``pack_bits`` output -> uint8 mask of ``shape`` with ink = 1 (padding bits are ignored)."""
    flat = np.unpackbits(np.frombuffer(bits, dtype=np.uint8), count=shape[0] * shape[1])
    return flat.reshape(shape)


def pack_rows(masks: np.ndarray) -> np.ndarray:
    """Masks ``[..., h, w]`` (nonzero = ink) -> uint8 ``[..., h, ceil(w / 8)]``, each row packed on its own."""
    return np.packbits(np.asarray(masks) != 0, axis=-1)


def unpack_rows(packed: np.ndarray, width: int) -> np.ndarray:
    """``pack_rows`` output -> uint8 masks ``[..., h, width]`` with ink = 1."""
    return np.unpackbits(np.asarray(packed, dtype=np.uint8), axis=-1, count=width).astype(np.uint8)
