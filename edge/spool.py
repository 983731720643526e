"""Bounded on-disk spool of encoded messages not yet acknowledged by the cloud.

Every message is written here *before* it goes on the wire and deleted only when the cloud's
cumulative ack covers its sequence number, so a network drop, a cloud restart or an edge restart
loses nothing. SQLite in WAL mode gives crash-safe appends without hand-written segment files;
``synchronous=NORMAL`` survives a killed process (a power cut may lose the last transactions).

The spool also owns the sequence counter and the session id, so both survive a restart and the
cloud can drop duplicates by ``seq``. When the bound is reached the oldest messages are dropped
and counted (``dropped``): a bounded device cannot promise more than its disk.

Every write is one transaction: when it fails (a full disk, a read-only remount) it is rolled back
and raised as a :class:`~darkread.edge.errors.SpoolError` naming the spool and the cause, so the
counts stay true and the connection never stays inside ``BEGIN``. One edge at a time holds a
spool directory (``spool.lock``): two processes numbering one seq space would overwrite each other.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import logging
import os
import sqlite3
import threading
import uuid
import weakref
from collections.abc import Iterator, Mapping
from pathlib import Path

from darkread.edge.errors import SpoolError

logger = logging.getLogger(__name__)

DEFAULT_MAX_BYTES = 256 * 1024 * 1024
DEFAULT_MAX_MESSAGES = 200_000
SPOOL_FILE = "spool.sqlite3"
LOCK_FILE = "spool.lock"
MEMORY = ":memory:"  # ``[uplink] spool_dir`` / ``--spool`` value for a spool in memory (lost at exit)

_SCHEMA = """
CREATE TABLE IF NOT EXISTS messages (seq INTEGER PRIMARY KEY, payload BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""


def default_spool_dir(environ: Mapping[str, str] | None = None) -> Path:
    """``$XDG_STATE_HOME/darkread/spool``, else ``~/.local/state/darkread/spool``: state that
    must survive a restart but is no user data (the XDG base directory specification)."""
    environ = os.environ if environ is None else environ
    state = environ.get("XDG_STATE_HOME", "")
    if state and Path(state).is_absolute():  # the specification ignores relative paths
        return Path(state) / "darkread" / "spool"
    home = environ.get("HOME", "")
    if not home:
        try:
            home = str(Path.home())
        except RuntimeError:
            raise ValueError("no home directory for the default spool: pass --spool DIR") from None
    return Path(home) / ".local" / "state" / "darkread" / "spool"


def spool_directory(setting: str, environ: Mapping[str, str] | None = None) -> Path | None:
    """Where ``[uplink] spool_dir`` puts the spool: that directory, the user's state directory
    when empty, or None (in memory) for ``:memory:``."""
    if setting == MEMORY:
        return None
    return Path(setting) if setting else default_spool_dir(environ)


def failure_cause(exc: BaseException, directory: Path | None) -> str:
    """Why a spool operation failed, in words: the file system's state (read-only, full) first,
    then SQLite's or the system's own message."""
    detail = (exc.strerror or str(exc)) if isinstance(exc, OSError) else str(exc)
    code = getattr(exc, "sqlite_errorcode", None)
    read_only = False
    if directory is not None:
        with contextlib.suppress(OSError):
            read_only = bool(os.statvfs(directory).f_flag & os.ST_RDONLY)
    if read_only or (isinstance(exc, OSError) and exc.errno == errno.EROFS) or code == sqlite3.SQLITE_READONLY:
        return _with_detail("read-only file system", detail)
    if code == sqlite3.SQLITE_FULL or (isinstance(exc, OSError) and exc.errno == errno.ENOSPC):
        return _with_detail("the disk is full", detail)
    return detail


def _close_lock(fd: int | None) -> None:
    if fd is not None:
        os.close(fd)  # closing the descriptor releases the lock


def _with_detail(cause: str, detail: str) -> str:
    return cause if detail.lower() == cause.lower() else f"{cause} ({detail})"


class Spool:
    """Thread-safe, bounded, persistent ``seq -> payload`` store.

    ``directory=None`` keeps the spool in memory (tests, or when asked: ``--spool :memory:``); what
    it still holds at :meth:`close` is lost, and counted in ``dropped``.
    """

    def __init__(
        self,
        directory: Path | str | None,
        max_bytes: int = DEFAULT_MAX_BYTES,
        max_messages: int = DEFAULT_MAX_MESSAGES,
    ) -> None:
        if max_bytes <= 0 or max_messages <= 0:
            raise ValueError("spool bounds must be positive (max_bytes, max_messages)")
        self.max_bytes = max_bytes
        self.max_messages = max_messages
        self.directory = None if directory is None else Path(directory)
        self.path: Path | None = None if self.directory is None else self.directory / SPOOL_FILE
        self._lock = threading.Lock()
        # the lock file's descriptor, closed by close() or, for a spool dropped unclosed, by the collector
        self._holder = weakref.finalize(self, _close_lock, self._hold(self.directory) if self.directory is not None else None)
        try:
            self._db = sqlite3.connect(str(self.path or MEMORY), check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
            row = self._db.execute("SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0), MAX(seq) FROM messages").fetchone()
            last_seq_meta = self._meta("last_seq")
        except sqlite3.Error as exc:
            self._release()
            raise SpoolError(f"spool {self.where}: cannot be opened: {failure_cause(exc, self.directory)}") from exc
        self._depth, self._bytes = int(row[0]), int(row[1])
        # seqs start at 0 (the protocol's first seq); -1 means "none yet"
        last_seq = max(int(last_seq_meta or -1), -1 if row[2] is None else int(row[2]))
        self._next_seq = last_seq + 1
        self.dropped = 0
        if self._depth:
            logger.info("spool %s: %d messages (%d bytes) from a previous run", self.path, self._depth, self._bytes)

    @property
    def where(self) -> str:
        """The spool's file, or "in memory" (for log lines and errors)."""
        return str(self.path) if self.path is not None else "in memory"

    # -- sequence and session -------------------------------------------------------------
    def allocate_seq(self) -> int:
        """The next sequence number (strictly increasing across restarts within a session)."""
        with self._lock:
            seq = self._next_seq
            self._next_seq += 1
            return seq

    @property
    def last_allocated_seq(self) -> int:
        return self._next_seq - 1

    def session_id(self) -> str | None:
        with self._lock:
            return self._meta("session_id")

    def set_session_id(self, session_id: str) -> None:
        """Bind the spool to ``session_id``; a new session gets a new stream id (seq space), whose
        seqs start at 0 again when nothing is waiting: a session's seqs are contiguous from 0 (the
        cloud refuses gaps), so continuing the spool's count would make the uplink fill the new
        session with a placeholder for every message the spool ever sent."""
        with self._lock, self._writing(f"record session {session_id}"):
            if self._meta("session_id") != session_id or self._meta("stream_id") is None:
                self._set_meta("stream_id", uuid.uuid4().hex)
                if self._depth == 0:
                    self._set_meta("last_seq", "-1")
                    self._next_seq = 0
            self._set_meta("session_id", session_id)

    def stream_id(self) -> str:
        """Names this spool's seq space to the cloud (``hello.stream_id``): the session's owner."""
        with self._lock:
            value = self._meta("stream_id")
            if value is None:
                value = uuid.uuid4().hex
                with self._writing("record the stream id"):
                    self._set_meta("stream_id", value)
            return value

    # -- messages -------------------------------------------------------------------------
    def append(self, seq: int, payload: bytes) -> None:
        """Store one encoded message; drops the oldest ones when a bound would be exceeded."""
        with self._lock:
            with self._writing(f"store message seq {seq} ({len(payload)} bytes)"):
                self._db.execute("INSERT OR REPLACE INTO messages (seq, payload) VALUES (?, ?)", (seq, payload))
                self._set_meta("last_seq", str(max(seq, self._next_seq - 1)))
            self._depth += 1
            self._bytes += len(payload)
            if self._depth > self.max_messages or self._bytes > self.max_bytes:
                self._evict_oldest()

    def ack(self, upto_seq: int) -> int:
        """Delete every message with ``seq <= upto_seq`` (a cumulative ack); returns how many."""
        with self._lock:
            with self._writing(f"delete the messages the cloud acknowledged (up to seq {upto_seq})"):
                row = self._db.execute(
                    "SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0) FROM messages WHERE seq <= ?", (upto_seq,)
                ).fetchone()
                if row[0]:
                    self._db.execute("DELETE FROM messages WHERE seq <= ?", (upto_seq,))
                if upto_seq >= self._next_seq:
                    # the cloud knows more than we do (e.g. a spool wiped by hand): never reuse its seqs
                    self._set_meta("last_seq", str(upto_seq))
            self._depth -= int(row[0])
            self._bytes -= int(row[1])
            self._next_seq = max(self._next_seq, upto_seq + 1)
            return int(row[0])

    def pending(self, after_seq: int = -1, limit: int = 256) -> list[tuple[int, bytes]]:
        """Up to ``limit`` stored messages with ``seq > after_seq``, oldest first."""
        with self._lock:
            try:
                rows = self._db.execute(
                    "SELECT seq, payload FROM messages WHERE seq > ? ORDER BY seq LIMIT ?", (after_seq, limit)
                ).fetchall()
            except sqlite3.Error as exc:
                raise SpoolError(f"spool {self.where}: cannot read the messages to send: "
                                 f"{failure_cause(exc, self.directory)}") from exc
        return [(int(seq), bytes(payload)) for seq, payload in rows]

    def discard(self, seq: int) -> None:
        """Remove one message the cloud will never accept (e.g. larger than its limit); the
        uplink sends an empty placeholder under its seq, so the cloud sees no gap."""
        with self._lock:
            with self._writing(f"drop message seq {seq}"):
                row = self._db.execute("SELECT LENGTH(payload) FROM messages WHERE seq = ?", (seq,)).fetchone()
                if row is not None:
                    self._db.execute("DELETE FROM messages WHERE seq = ?", (seq,))
            if row is not None:
                self._depth -= 1
                self._bytes -= int(row[0])

    @property
    def depth(self) -> int:
        return self._depth

    @property
    def bytes_pending(self) -> int:
        return self._bytes

    @property
    def in_memory(self) -> bool:
        return self.path is None

    def close(self) -> None:
        """Close the database and free the directory; an in-memory spool's messages are lost
        here (counted in ``dropped``)."""
        with self._lock:
            self._db.close()
            if self.path is None and self._depth:
                logger.warning("in-memory spool closed with %d unsent messages: they are lost", self._depth)
                self.dropped += self._depth
                self._depth, self._bytes = 0, 0
            self._release()

    # -- the directory lock ---------------------------------------------------------------
    @staticmethod
    def _hold(directory: Path) -> int:
        """Create ``directory`` and hold its lock file (a descriptor): a clear error for a read-only
        or full disk, a file in the way, or another edge using it."""
        if directory.exists() and not directory.is_dir():
            raise ValueError(f"spool {directory} is a file, not a directory")
        try:
            directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(directory / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise SpoolError(f"spool {directory}: cannot be written: {failure_cause(exc, directory)}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise SpoolError(f"spool {directory} is in use by another edge (pid {pid}); "
                             "give each edge its own --spool DIR") from None
        with contextlib.suppress(OSError):  # the pid is a courtesy for the message above
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        return fd

    def _release(self) -> None:
        self._holder()  # runs once (or when the spool is garbage-collected unclosed)

    # -- internals (lock held) --------------------------------------------------------------
    @contextlib.contextmanager
    def _writing(self, action: str) -> Iterator[None]:
        """One write transaction; a failure is rolled back and raised as a :class:`SpoolError`
        naming the spool, what it was doing and why it failed."""
        try:
            self._db.execute("BEGIN IMMEDIATE")
            yield
            self._db.execute("COMMIT")
        except sqlite3.Error as exc:
            if self._db.in_transaction:
                with contextlib.suppress(sqlite3.Error):
                    self._db.execute("ROLLBACK")
            raise SpoolError(f"spool {self.where}: cannot {action}: {failure_cause(exc, self.directory)}") from exc

    def _evict_oldest(self) -> None:
        # evict down to 90 % of the bounds so a full spool does not evict on every append
        target_messages = int(self.max_messages * 0.9)
        target_bytes = int(self.max_bytes * 0.9)
        freed_bytes, n_evict, last = 0, 0, None
        cursor = self._db.execute("SELECT seq, LENGTH(payload) FROM messages ORDER BY seq")
        done = False
        while not done and (batch := cursor.fetchmany(1024)):
            for seq, size in batch:
                if self._depth - n_evict <= target_messages and self._bytes - freed_bytes <= target_bytes:
                    done = True
                    break
                freed_bytes += int(size)
                n_evict += 1
                last = int(seq)
        cursor.close()
        if last is not None:
            with self._writing(f"drop the oldest messages (up to seq {last}) from the full spool"):
                self._db.execute("DELETE FROM messages WHERE seq <= ?", (last,))
            self._depth -= n_evict
            self._bytes -= freed_bytes
            self.dropped += n_evict
            logger.warning("spool full: dropped %d oldest messages (up to seq %d)", n_evict, last)

    def _meta(self, key: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def _set_meta(self, key: str, value: str) -> None:
        self._db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, value))
