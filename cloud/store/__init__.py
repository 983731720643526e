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


async def open_store(data_dir: Path, database_url: str | None = None, *, timeout_s: float = 3.0,
                     read_threads: int = 4) -> SessionStore:  # fmt: skip
    """PostgreSQL when ``database_url`` is given (several instances share it), else SQLite in
    ``data_dir``. ``timeout_s``: a request's longest wait for a database connection."""
    if database_url:
        from .postgres import PostgresStore  # psycopg only where PostgreSQL is used

        return await PostgresStore.open(database_url, timeout_s=timeout_s)
    return SqliteStore(data_dir, read_threads=read_threads)


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
