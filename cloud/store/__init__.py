"""Durable storage of sessions: the ``SessionStore`` protocol, its records, and its backends."""

from pathlib import Path

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


async def open_store(data_dir: Path, database_url: str | None = None) -> SessionStore:
    """PostgreSQL when ``database_url`` is given (several instances share it), else SQLite in ``data_dir``."""
    if database_url:
        from .postgres import PostgresStore  # psycopg only where PostgreSQL is used

        return await PostgresStore.open(database_url)
    return SqliteStore(data_dir)


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
    "open_store",
]
