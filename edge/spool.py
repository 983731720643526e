"""Bounded on-disk spool of encoded messages not yet acknowledged by the cloud.

Every message is written here *before* it goes on the wire and deleted only when the cloud's
cumulative ack covers its sequence number, so a network drop, a cloud restart or an edge restart
loses nothing. SQLite in WAL mode gives crash-safe appends without hand-written segment files;
``synchronous=NORMAL`` survives a killed process (a power cut may lose the last transactions).

The spool also owns the sequence counter and the session id, so both survive a restart and the
cloud can drop duplicates by ``seq``. When the bound is reached the oldest messages are dropped
and counted (``dropped``): a bounded device cannot promise more than its disk.
"""

from __future__ import annotations

import logging
import sqlite3
import threading
import uuid
from pathlib import Path

logger = logging.getLogger(__name__)

DEFAULT_MAX_BYTES = 256 * 1024 * 1024
DEFAULT_MAX_MESSAGES = 200_000
SPOOL_FILE = "spool.sqlite3"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS messages (seq INTEGER PRIMARY KEY, payload BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""


class Spool:
    """Thread-safe, bounded, persistent ``seq -> payload`` store.

    ``directory=None`` keeps the spool in memory (tests, or a device without writable storage).
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
        if directory is None:
            self.path: Path | None = None
            target = ":memory:"
        else:
            if Path(directory).exists() and not Path(directory).is_dir():
                raise ValueError(f"spool {directory} is a file, not a directory")
            try:
                Path(directory).mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise ValueError(f"spool directory {directory} cannot be created: {exc.strerror or exc}") from None
            self.path = Path(directory) / SPOOL_FILE
            target = str(self.path)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(target, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)
        row = self._db.execute("SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0), MAX(seq) FROM messages").fetchone()
        self._depth, self._bytes = int(row[0]), int(row[1])
        # seqs start at 0 (the protocol's first seq); -1 means "none yet"
        last_seq = max(int(self._meta("last_seq") or -1), -1 if row[2] is None else int(row[2]))
        self._next_seq = last_seq + 1
        self.dropped = 0
        if self._depth:
            logger.info("spool %s: %d messages (%d bytes) from a previous run", target, self._depth, self._bytes)

    # -- sequence and session -------------------------------------------------------------
    def allocate_seq(self) -> int:
        """The next sequence number (strictly increasing across restarts)."""
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
        """Bind the spool to ``session_id``; a new session gets a new stream id (seq space)."""
        with self._lock:
            if self._meta("session_id") != session_id or self._meta("stream_id") is None:
                self._set_meta("stream_id", uuid.uuid4().hex)
            self._set_meta("session_id", session_id)

    def stream_id(self) -> str:
        """Names this spool's seq space to the cloud (``hello.stream_id``): the session's owner."""
        with self._lock:
            value = self._meta("stream_id")
            if value is None:
                value = uuid.uuid4().hex
                self._set_meta("stream_id", value)
            return value

    # -- messages -------------------------------------------------------------------------
    def append(self, seq: int, payload: bytes) -> None:
        """Store one encoded message; drops the oldest ones when a bound would be exceeded."""
        with self._lock:
            self._db.execute("BEGIN")
            self._db.execute("INSERT OR REPLACE INTO messages (seq, payload) VALUES (?, ?)", (seq, payload))
            self._set_meta("last_seq", str(max(seq, self._next_seq - 1)))
            self._db.execute("COMMIT")
            self._depth += 1
            self._bytes += len(payload)
            if self._depth > self.max_messages or self._bytes > self.max_bytes:
                self._evict_oldest()

    def ack(self, upto_seq: int) -> int:
        """Delete every message with ``seq <= upto_seq`` (a cumulative ack); returns how many."""
        with self._lock:
            row = self._db.execute(
                "SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0) FROM messages WHERE seq <= ?", (upto_seq,)
            ).fetchone()
            if row[0]:
                self._db.execute("DELETE FROM messages WHERE seq <= ?", (upto_seq,))
                self._depth -= int(row[0])
                self._bytes -= int(row[1])
            if upto_seq >= self._next_seq:
                # the cloud knows more than we do (e.g. a spool wiped by hand): never reuse its seqs
                self._next_seq = upto_seq + 1
                self._set_meta("last_seq", str(upto_seq))
            return int(row[0])

    def pending(self, after_seq: int = -1, limit: int = 256) -> list[tuple[int, bytes]]:
        """Up to ``limit`` stored messages with ``seq > after_seq``, oldest first."""
        with self._lock:
            rows = self._db.execute(
                "SELECT seq, payload FROM messages WHERE seq > ? ORDER BY seq LIMIT ?", (after_seq, limit)
            ).fetchall()
        return [(int(seq), bytes(payload)) for seq, payload in rows]

    def discard(self, seq: int) -> None:
        """Remove one message the cloud will never accept (e.g. larger than its limit); the
        uplink sends an empty placeholder under its seq, so the cloud sees no gap."""
        with self._lock:
            row = self._db.execute("SELECT LENGTH(payload) FROM messages WHERE seq = ?", (seq,)).fetchone()
            if row is not None:
                self._db.execute("DELETE FROM messages WHERE seq = ?", (seq,))
                self._depth -= 1
                self._bytes -= int(row[0])

    @property
    def depth(self) -> int:
        return self._depth

    @property
    def bytes_pending(self) -> int:
        return self._bytes

    def close(self) -> None:
        with self._lock:
            self._db.close()

    # -- internals (lock held) --------------------------------------------------------------
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
