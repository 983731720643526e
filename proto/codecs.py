"""How masks and grey-level views are compressed on the wire (protocol version 2).

A binary mask is always held as ``mask_bits.pack_bits`` output (the v1 layout); on the wire it
goes as that (``"bits"``), zlib of it (``"zlib"``) or a 1-bit PNG (``"png"``, black = ink). A view's
grey levels (one byte per pixel, each < ``n_levels``) go as an 8-bit grey PNG of the level
indices (``"png"``) or zlib of the bytes (``"zlib"``).

Decoding is hostile-input safe: zlib is inflated with a length bound (a small message cannot
expand into gigabytes), a PNG's header is read and checked against the declared shape before any
pixel is decoded, and every failure is a ``BadMaskError``.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from darkread.image_codec import ImageCodecError, decode_image, encode_png, encode_png_bilevel
from darkread.mask_bits import pack_bits, packed_length, unpack_bits

from .errors import BadMaskError

MASK_ENCODINGS = ("bits", "zlib", "png")
LEVEL_ENCODINGS = ("png", "zlib")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
ZLIB_LEVEL = 6


def _inflate(data: bytes, size: int) -> bytes:
    """zlib ``data`` that must inflate to exactly ``size`` bytes (bounded: no decompression bomb)."""
    inflater = zlib.decompressobj()
    try:
        out = inflater.decompress(data, size + 1)
    except zlib.error as exc:
        raise BadMaskError(f"zlib data is corrupt ({exc})") from None
    if len(out) != size or not inflater.eof or inflater.unconsumed_tail or inflater.unused_data:
        raise BadMaskError(f"zlib data must inflate to exactly {size} bytes and end there")
    return out


def png_header(data: bytes) -> tuple[int, int, int, int]:
    """(width, height, bit depth, colour type) from a PNG's IHDR, without decoding a pixel."""
    if len(data) < 33 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        raise BadMaskError("not a PNG (signature or IHDR missing)")
    width, height, depth, colour = struct.unpack(">IIBB", data[16:26])
    return width, height, depth, colour


def _decode_png(data: bytes, shape: tuple[int, int], depths: tuple[int, ...]) -> np.ndarray:
    width, height, depth, colour = png_header(data)
    if (height, width) != shape:
        raise BadMaskError(f"PNG of {width}x{height} does not match the shape {shape}")
    if colour != 0 or depth not in depths:
        raise BadMaskError(f"PNG must be greyscale of bit depth {depths}, got colour type {colour}, depth {depth}")
    try:
        image = decode_image(data)
    except ImageCodecError as exc:
        raise BadMaskError(f"PNG does not decode: {exc}") from None
    if image.shape != shape:
        raise BadMaskError(f"PNG decoded to {image.shape}, not {shape}")
    return image


def compress_bits(shape: tuple[int, int], bits: bytes, enc: str) -> bytes:
    """Packed mask bits -> their wire form under ``enc``."""
    if enc == "bits":
        return bits
    if enc == "zlib":
        return zlib.compress(bits, ZLIB_LEVEL)
    if enc == "png":
        ink = unpack_bits(shape, bits)
        return encode_png_bilevel(np.where(ink > 0, 0, 255).astype(np.uint8))
    raise BadMaskError(f"unknown mask encoding {enc!r} (known: {', '.join(MASK_ENCODINGS)})")


def decompress_bits(shape: tuple[int, int], data: bytes, enc: str) -> bytes:
    """The wire form of a ``shape`` mask under ``enc`` -> packed bits (checked)."""
    if enc == "bits":
        return data
    if enc == "zlib":
        return _inflate(data, packed_length(shape))
    if enc == "png":
        return pack_bits(_decode_png(data, shape, (1, 8)) < 128)
    raise BadMaskError(f"unknown mask encoding {enc!r} (known: {', '.join(MASK_ENCODINGS)})")


def compress_levels(shape: tuple[int, int], levels: bytes, enc: str) -> bytes:
    """One level index per pixel (row-major bytes) -> the wire form under ``enc``."""
    if enc == "png":
        return encode_png(np.frombuffer(levels, np.uint8).reshape(shape))
    if enc == "zlib":
        return zlib.compress(levels, ZLIB_LEVEL)
    raise BadMaskError(f"unknown level encoding {enc!r} (known: {', '.join(LEVEL_ENCODINGS)})")


def decompress_levels(shape: tuple[int, int], data: bytes, enc: str) -> bytes:
    """The wire form of a view's levels -> one byte per pixel (range checked by the message)."""
    if enc == "png":
        return _decode_png(data, shape, (8,)).tobytes()
    if enc == "zlib":
        return _inflate(data, shape[0] * shape[1])
    raise BadMaskError(f"unknown level encoding {enc!r} (known: {', '.join(LEVEL_ENCODINGS)})")
