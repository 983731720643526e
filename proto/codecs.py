"""How masks and grey-level views are compressed on the wire (protocol version 2).

A binary mask is always held as ``mask_bits.pack_bits`` output (the v1 layout); on the wire it
goes as that (``"bits"``), zlib of it (``"zlib"``), a 1-bit PNG (``"png"``, black = ink) or, from
version 3, a bare CCITT Group 4 stream (``"g4"``, ITU-T T.6, ink = black: the fax code for text, the
smallest of them on stitched pages). A view's grey levels (one byte per pixel, each < ``n_levels``)
go as an 8-bit grey PNG of the level indices (``"png"``) or zlib of the bytes (``"zlib"``).

Decoding is hostile-input safe: zlib is inflated with a length bound (a small message cannot
expand into gigabytes), a PNG's header is read and checked against the declared shape before any
pixel is decoded, a G4 stream carries no size of its own (the decoder wraps it in a TIFF header
built from the message's ``shape``, already checked against the protocol's limits) and must end
with T.6's end-of-block code (a cut stream is refused), and every failure is a ``BadMaskError``.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
from PIL import Image, TiffImagePlugin

from darkread.core.image_codec import ImageCodecError, decode_image, encode_png, encode_png_bilevel
from darkread.core.mask_bits import pack_bits, packed_length, unpack_bits

from .errors import BadMaskError

MASK_ENCODINGS = ("bits", "zlib", "png", "g4")
LEVEL_ENCODINGS = ("png", "zlib")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
ZLIB_LEVEL = 6
G4_EOFB = 0x001001  # T.6 end of facsimile block: two EOL codes, 000000000001 000000000001
_TIFF_TAGS = {"width": 256, "height": 257, "bits": 258, "compression": 259, "photometric": 262,
              "offsets": 273, "samples": 277, "rows_per_strip": 278, "byte_counts": 279}  # fmt: skip
_PIL_ERRORS = (OSError, ValueError, SyntaxError, EOFError, struct.error, Image.DecompressionBombError)


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


def encode_g4(shape: tuple[int, int], bits: bytes) -> bytes:
    """Packed mask bits -> the bare T.6 (Group 4) stream of the mask, ink coded as black.

    libtiff (in Pillow's wheels) writes it as the single strip of a TIFF; the strip is the stream.
    Pillow codes a mode-"1" pixel of value 1 as a fax *black* run, so the ink goes in as 1.
    """
    ink = unpack_bits(shape, bits).astype(bool)
    out = io.BytesIO()
    Image.fromarray(ink).save(out, "TIFF", compression="group4", strip_size=max(1, ink.size))  # one strip
    tiff_bytes = out.getvalue()
    with Image.open(io.BytesIO(tiff_bytes)) as tiff:
        assert isinstance(tiff, TiffImagePlugin.TiffImageFile)  # written as a TIFF just above
        offsets, counts = tiff.tag_v2[_TIFF_TAGS["offsets"]], tiff.tag_v2[_TIFF_TAGS["byte_counts"]]
    if len(offsets) != 1:
        raise RuntimeError(f"Pillow wrote {len(offsets)} G4 strips, not one (Pillow too old for strip_size?)")
    return tiff_bytes[offsets[0]:offsets[0] + counts[0]]


def g4_tiff(shape: tuple[int, int], stream: bytes) -> bytes:
    """A bare G4 stream -> a one-strip TIFF of ``shape`` around it (the size comes from us, not the stream)."""
    height, width = shape
    short, long = 3, 4
    tags = [  # ascending tag order, as TIFF requires; photometric 1 (BlackIsZero): Pillow's reading of fax black = 1
        ("width", long, width), ("height", long, height), ("bits", short, 1), ("compression", short, 4),
        ("photometric", short, 1), ("offsets", long, 8), ("samples", short, 1), ("rows_per_strip", long, height),
        ("byte_counts", long, len(stream)),
    ]
    entries = b"".join(
        struct.pack("<HHII", _TIFF_TAGS[name], kind, 1, value) if kind == long
        else struct.pack("<HHIHH", _TIFF_TAGS[name], kind, 1, value, 0)
        for name, kind, value in tags
    )
    return b"II*\0" + struct.pack("<I", 8 + len(stream)) + stream + struct.pack("<H", len(tags)) + entries + b"\0" * 4


def _ends_with_eofb(stream: bytes) -> bool:
    """Whether the stream ends with T.6's EOFB followed by less than a byte of zero padding."""
    tail = int.from_bytes(stream[-4:], "big")
    if len(stream) < 3 or tail == 0:
        return False
    padding = (tail & -tail).bit_length() - 1
    return padding < 8 and (tail >> padding) & 0xFFFFFF == G4_EOFB


def decode_g4(shape: tuple[int, int], stream: bytes) -> bytes:
    """A bare G4 stream of a ``shape`` mask -> packed bits; anything else is a ``BadMaskError``."""
    if not _ends_with_eofb(stream):
        raise BadMaskError(f"G4 stream of {len(stream)} bytes does not end with the end-of-block code (cut or not G4)")
    try:
        with Image.open(io.BytesIO(g4_tiff(shape, stream))) as image:
            image.load()
            pixels = np.asarray(image)
    except _PIL_ERRORS as exc:
        raise BadMaskError(f"G4 stream does not decode ({type(exc).__name__}: {exc})"[:300]) from None
    if pixels.shape != shape:
        raise BadMaskError(f"G4 stream decoded to {pixels.shape}, not {shape}")
    return pack_bits(pixels)


def compress_bits(shape: tuple[int, int], bits: bytes, enc: str) -> bytes:
    """Packed mask bits -> their wire form under ``enc``."""
    if enc == "bits":
        return bits
    if enc == "zlib":
        return zlib.compress(bits, ZLIB_LEVEL)
    if enc == "png":
        ink = unpack_bits(shape, bits)
        return encode_png_bilevel(np.where(ink > 0, 0, 255).astype(np.uint8))
    if enc == "g4":
        return encode_g4(shape, bits)
    raise BadMaskError(f"unknown mask encoding {enc!r} (known: {', '.join(MASK_ENCODINGS)})")


def decompress_bits(shape: tuple[int, int], data: bytes, enc: str) -> bytes:
    """The wire form of a ``shape`` mask under ``enc`` -> packed bits (checked)."""
    if enc == "bits":
        return data
    if enc == "zlib":
        return _inflate(data, packed_length(shape))
    if enc == "png":
        return pack_bits(_decode_png(data, shape, (1, 8)) < 128)
    if enc == "g4":
        return decode_g4(shape, data)
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
