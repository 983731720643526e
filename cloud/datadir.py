"""The data directory: checked before the service starts, and held by one process at a time.

SQLite with one writer thread cannot be shared safely by two service processes (their in-memory
resume points diverge: duplicate keys, lost acks), so a second ``darkread cloud serve`` on the
same directory is refused at start: ``<data dir>/.lock`` is held with ``flock`` for the life of
the process (the kernel drops it when the process dies, even by SIGKILL).
"""

from __future__ import annotations

import fcntl
import os
import sqlite3
import threading
from pathlib import Path

from .errors import DataDirError

LOCK_FILE = ".lock"
DATABASE = "darkread.sqlite3"

_held: dict[Path, tuple[int, int]] = {}  # resolved dir -> (lock fd, users in this process)
_held_lock = threading.Lock()


def check_data_dir(data_dir: Path) -> None:
    """Create ``data_dir`` if needed and prove it usable: a writable directory whose database
    (if any) is a SQLite file that passes ``quick_check``. DataDirError (one line) otherwise."""
    if data_dir.exists() and not data_dir.is_dir():
        raise DataDirError(f"data directory {data_dir} is a file, not a directory")
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        probe = data_dir / f".write-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise DataDirError(f"data directory {data_dir} cannot be created or written: {exc.strerror or exc}") from None
    database = data_dir / DATABASE
    if database.exists():
        try:
            with sqlite3.connect(f"file:{database}?mode=ro", uri=True, timeout=5) as db:
                verdict = db.execute("PRAGMA quick_check").fetchone()[0]
        except sqlite3.DatabaseError as exc:
            raise DataDirError(f"data directory {data_dir}: {DATABASE} is unreadable or corrupt ({exc})") from None
        if verdict != "ok":
            raise DataDirError(f"data directory {data_dir}: {DATABASE} is corrupt ({verdict})")


def acquire(data_dir: Path) -> Path:
    """Hold the directory's lock (re-entrant within this process); DataDirError when another
    process holds it, naming its pid."""
    key = data_dir.resolve()
    with _held_lock:
        if key in _held:
            fd, users = _held[key]
            _held[key] = (fd, users + 1)
            return key
        fd = os.open(key / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise DataDirError(
                f"another darkread cloud (pid {owner}) is using the data directory {data_dir}; one process per "
                "SQLite data directory (stop it, or give this one its own --data-dir)"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _held[key] = (fd, 1)
        return key


def release(key: Path) -> None:
    with _held_lock:
        if key not in _held:
            return
        fd, users = _held[key]
        if users > 1:
            _held[key] = (fd, users - 1)
            return
        del _held[key]
        os.close(fd)  # closing the descriptor releases the flock
