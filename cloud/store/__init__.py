"""Durable storage of sessions: the ``SessionStore`` protocol, its records, and its backends."""

from .blobs import BlobStore, FileBlobs
from .protocol import SessionStore
from .records import (
    GazeRecord,
    PageBreak,
    PageRecord,
    SessionInfo,
    SessionOwnedError,
    SessionShapeError,
    SessionSpec,
    StoredFrame,
    StoreError,
    UnknownSessionError,
    WriteResult,
)
from .sqlite import SqliteStore


__all__ = [
    "BlobStore",
    "FileBlobs",
    "GazeRecord",
    "PageBreak",
    "PageRecord",
    "SessionInfo",
    "SessionOwnedError",
    "SessionShapeError",
    "SessionSpec",
    "SessionStore",
    "SqliteStore",
    "StoreError",
    "StoredFrame",
    "UnknownSessionError",
    "WriteResult",
]
