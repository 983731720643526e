"""Page images and other large values, kept beside the database under a key.

A backend stores only the key in its rows; where the bytes live (a directory, an object store)
is this small interface's business.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path
from typing import Protocol

import numpy as np

from darkread.core.image_codec import ImageCodecError, decode_image

from ..errors import StoreError

_KEY = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*(/[A-Za-z0-9][A-Za-z0-9._-]*)*")


class BlobStore(Protocol):
    """Bytes under slash-separated keys. Blocking: backends call it from their worker threads."""

    def put(self, key: str, data: bytes) -> None:
        """Durably store ``data`` (on disk before it returns)."""

    def get(self, key: str) -> bytes:
        """The bytes under ``key``; StoreError if there are none."""

    def delete_prefix(self, prefix: str) -> None:
        """Remove every blob whose key starts with ``prefix/``."""


class FileBlobs:
    """Blobs as files under ``root`` (written to a temporary name, fsynced, renamed)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        if not _KEY.fullmatch(key):
            raise StoreError(f"blob key {key!r} is not a relative slash-separated name")
        return self.root / key

    def put(self, key: str, data: bytes) -> None:
        path = self._path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)

    def get(self, key: str) -> bytes:
        try:
            return self._path(key).read_bytes()
        except OSError as exc:
            raise StoreError(f"blob {key!r} is missing or unreadable: {exc.strerror}") from None

    def delete_prefix(self, prefix: str) -> None:
        shutil.rmtree(self._path(prefix), ignore_errors=True)


def decode_mask_png(data: bytes, key: str) -> np.ndarray:
    """PNG bytes (black text on white) -> uint8 ink mask, ink = 1."""
    try:
        image = decode_image(data)
    except ImageCodecError as exc:
        raise StoreError(f"page image {key!r} is not a readable PNG: {exc}") from exc
    return (image < 128).astype(np.uint8)


def page_key(session_id: str, seq: int) -> str:
    """Where a session's page sent at ``seq`` lives: the same key on every backend."""
    return f"pages/{session_id}/{seq}.png"
