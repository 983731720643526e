"""PNG and JPEG in one place, with one exception (``ImageCodecError``).

Images are uint8 numpy arrays: ``[h, w]`` grey or ``[h, w, 3]`` RGB (OpenCV's BGR order stays
inside this module). Pages, OCR requests, the RGB baseline and the bandwidth figures all encode
through here, so a page sent, stored and measured is the same bytes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from darkread.core.errors import DarkreadError


class ImageCodecError(DarkreadError):
    """An image that cannot be encoded, or bytes or a file that are not a readable image."""


def _cv2() -> Any:
    """OpenCV, imported on first use: the wire protocol imports this module, and a peer that never
    sees a PNG (the glasses decoding acks) need not load it."""
    import cv2  # lazy: OpenCV loads when an image is first encoded or decoded

    return cv2


def _to_opencv(image: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(image)
    if array.dtype != np.uint8 or not (array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 3)):
        raise ImageCodecError(f"expected a uint8 [h, w] or [h, w, 3] image, got {array.dtype} {array.shape}")
    if array.size == 0:
        raise ImageCodecError(f"cannot encode an empty image of shape {array.shape}")
    return array[..., ::-1] if array.ndim == 3 else array


def _from_opencv(image: np.ndarray | None, what: str) -> np.ndarray:
    if image is None:
        raise ImageCodecError(f"{what}: not a readable image")
    return np.ascontiguousarray(image[..., ::-1]) if image.ndim == 3 else image


def _encode(extension: str, image: np.ndarray, params: list[int] | None = None) -> bytes:
    ok, buf = _cv2().imencode(extension, _to_opencv(image), params or [])
    if not ok:
        raise ImageCodecError(f"{extension[1:].upper()} encoding of a {image.dtype} {image.shape} image failed")
    return buf.tobytes()


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG of a grey or RGB uint8 image."""
    return _encode(".png", image)


def encode_png_bilevel(image: np.ndarray) -> bytes:
    """1-bit PNG of a grey image (values >= 128 white): text pages and masks at an eighth of 8-bit PNG."""
    cv2 = _cv2()
    return _encode(".png", image, [cv2.IMWRITE_PNG_BILEVEL, 1, cv2.IMWRITE_PNG_COMPRESSION, 9])


def encode_jpeg(image: np.ndarray, quality: int) -> bytes:
    """JPEG at ``quality`` (0-100) of a grey or RGB uint8 image."""
    return _encode(".jpg", image, [_cv2().IMWRITE_JPEG_QUALITY, int(quality)])


def decode_image(data: bytes, *, colour: bool = False) -> np.ndarray:
    """PNG or JPEG bytes -> uint8 grey ``[h, w]``, or RGB ``[h, w, 3]`` with ``colour``."""
    cv2 = _cv2()
    flag = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
    return _from_opencv(cv2.imdecode(np.frombuffer(data, np.uint8), flag), f"{len(data)} bytes")


def read_image(path: str | Path, *, colour: bool = False) -> np.ndarray:
    """An image file -> uint8 grey, or RGB with ``colour``; ``ImageCodecError`` if missing or unreadable."""
    cv2 = _cv2()
    flag = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
    return _from_opencv(cv2.imread(str(path), flag), str(path))


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write ``image`` as a PNG file (grey or RGB)."""
    path = Path(path)
    path.write_bytes(encode_png(image))
    return path
