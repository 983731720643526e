"""Durable storage of sessions, frames, pages and gaze batches: SQLite plus page PNGs on disk.

One writer thread owns the write connection and commits in groups: every message waiting when
a transaction starts goes into the same commit, so many concurrent streams share each fsync
while every ack still follows its own commit. Readers use their own short-lived connections
(WAL lets them run beside the writer).

Layout under ``data_dir``::

    darkread.sqlite3          sessions, frames (mask bits + metadata), pages, gaze
    pages/<session>/<seq>.png pages sent by the glasses (black text on white)
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import queue
import shutil
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from darkread.frame_record import FrameRecord
from darkread.image_codec import ImageCodecError, encode_png, read_image
from darkread.mask_bits import unpack_bits
from darkread.proto.messages import Frame, Gaze, Hello, Page
from darkread.stitch.stitched_page import ink_mask_to_paper

from .errors import SessionOwnedError, SessionShapeError, StoreError

log = logging.getLogger(__name__)

SCHEMA = """
CREATE TABLE IF NOT EXISTS sessions (
    session_id TEXT PRIMARY KEY,
    device_id TEXT NOT NULL,
    mode TEXT NOT NULL,
    sensor_w INTEGER NOT NULL, sensor_h INTEGER NOT NULL,
    fovea_h INTEGER NOT NULL, fovea_w INTEGER NOT NULL,
    created_s REAL NOT NULL, updated_s REAL NOT NULL,
    last_seq INTEGER NOT NULL DEFAULT -1,
    stream_id TEXT NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS frames (
    session_id TEXT NOT NULL, seq INTEGER NOT NULL,
    frame_id INTEGER NOT NULL, t_us INTEGER NOT NULL,
    x0 INTEGER NOT NULL, y0 INTEGER NOT NULL,
    gaze_u REAL NOT NULL, gaze_v REAL NOT NULL, yaw REAL NOT NULL, pitch REAL NOT NULL,
    events_used INTEGER NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, bits BLOB NOT NULL,
    PRIMARY KEY (session_id, seq)
);
CREATE TABLE IF NOT EXISTS pages (
    session_id TEXT NOT NULL, seq INTEGER NOT NULL, page_id INTEGER NOT NULL, t_us INTEGER NOT NULL,
    rows INTEGER NOT NULL, cols INTEGER NOT NULL, png_path TEXT NOT NULL, lines TEXT NOT NULL,
    PRIMARY KEY (session_id, seq)
);
CREATE TABLE IF NOT EXISTS gaze (
    session_id TEXT NOT NULL, seq INTEGER NOT NULL, samples BLOB NOT NULL,
    PRIMARY KEY (session_id, seq)
);
"""


def check_owner(hello: Hello, device_id: str, stream_id: str, mode: str, sensor: tuple[int, int],
                fovea: tuple[int, int]) -> None:
    """Raise unless ``hello`` may resume the stored session: same device, same stream (seq
    space; '' = a client that sends none), same mode and geometry."""
    if hello.device_id != device_id:
        raise SessionOwnedError(f"session {hello.session_id!r} belongs to device {device_id!r}")
    if (hello.stream_id or "") != stream_id:
        raise SessionOwnedError(
            f"session {hello.session_id!r} belongs to another stream of {device_id!r} (another spool, whose seqs "
            "would collide); use a new session id"
        )
    wanted, stored = (hello.mode, tuple(hello.sensor), tuple(hello.fovea)), (mode, sensor, fovea)
    if wanted != stored:
        raise SessionShapeError(
            f"session {hello.session_id!r} is {mode} with sensor {sensor} and fovea {fovea}; hello says {wanted[0]} "
            f"with sensor {wanted[1]} and fovea {wanted[2]}"
        )


@dataclass(frozen=True)
class SessionInfo:
    session_id: str
    device_id: str
    mode: str
    sensor: tuple[int, int]  # (width, height)
    fovea: tuple[int, int]  # (height, width)
    created_s: float
    updated_s: float
    last_seq: int
    frames: int
    pages: int


@dataclass(frozen=True)
class StoredFrame(FrameRecord):
    """A frame record as the session stored it, with the sequence number it arrived under."""

    seq: int


@dataclass(frozen=True)
class StoredPage:
    seq: int
    page_id: int
    t_us: int
    png_path: Path
    lines: list[tuple[int, int, int, int]]

    def image(self) -> np.ndarray:
        """The page as uint8 black-on-white (0 = ink, 255 = paper)."""
        try:
            return read_image(self.png_path)
        except ImageCodecError as exc:
            raise StoreError(f"page image {self.png_path} is missing or unreadable") from exc


@dataclass(frozen=True)
class WriteResult:
    stored: bool  # False for a duplicate seq
    last_seq: int  # highest seq durably stored for the session (the cumulative ack)


def mask_to_png(mask: np.ndarray) -> bytes:
    """Ink mask (nonzero = ink) -> PNG bytes, black text on white."""
    return encode_png(ink_mask_to_paper(mask))


def _fsync_write(path: Path, data: bytes) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


_Job = tuple[Callable[[sqlite3.Connection], Any], Callable[[Any, BaseException | None], None]]


class Store:
    """Sessions, frames and pages of every stream. Thread-safe; writes go through one thread."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = Path(data_dir)
        self.pages_dir = self.data_dir / "pages"
        self.pages_dir.mkdir(parents=True, exist_ok=True)
        self.db_path = self.data_dir / "darkread.sqlite3"
        self._jobs: queue.Queue[_Job | None] = queue.Queue()
        self._last_seq: dict[str, int] = {}
        self._closed = False
        with closing(self._connect()) as conn:
            conn.executescript(SCHEMA)
            columns = {row[1] for row in conn.execute("PRAGMA table_info(sessions)")}
            if "stream_id" not in columns:  # databases from before session ownership
                conn.execute("ALTER TABLE sessions ADD COLUMN stream_id TEXT NOT NULL DEFAULT ''")
            conn.execute("PRAGMA journal_mode=WAL")
            self._last_seq = dict(conn.execute("SELECT session_id, last_seq FROM sessions"))
        self._writer = threading.Thread(target=self._write_loop, name="darkread-store-writer", daemon=True)
        self._writer.start()

    # --- plumbing -----------------------------------------------------------------------------

    def _connect(self) -> sqlite3.Connection:
        # Autocommit mode: transactions are explicit (BEGIN/COMMIT in the writer), so a savepoint
        # never commits on its own.
        conn = sqlite3.connect(self.db_path, timeout=30, check_same_thread=False, isolation_level=None)
        conn.execute("PRAGMA synchronous=FULL")  # a commit is on disk before we ack
        return conn

    @contextmanager
    def _reader(self) -> Iterator[sqlite3.Connection]:
        with closing(self._connect()) as conn:
            yield conn

    def _write_loop(self) -> None:
        conn = self._connect()
        try:
            while True:
                job = self._jobs.get()
                if job is None:
                    return
                batch = [job]
                while len(batch) < 512:  # group commit: take everything already waiting
                    try:
                        more = self._jobs.get_nowait()
                    except queue.Empty:
                        break
                    if more is None:
                        self._jobs.put(None)
                        break
                    batch.append(more)
                self._run_batch(conn, batch)
        finally:
            conn.close()

    def _run_batch(self, conn: sqlite3.Connection, batch: list[_Job]) -> None:
        """One transaction, one commit (one fsync) for the whole batch; a failing job rolls back
        only its own savepoint and reports its error to its own caller."""
        results: list[tuple[Callable[[Any, BaseException | None], None], Any, BaseException | None]] = []
        seqs_before = dict(self._last_seq)
        try:
            conn.execute("BEGIN IMMEDIATE")
            for work, done in batch:
                conn.execute("SAVEPOINT job")
                try:
                    value = work(conn)
                except Exception as exc:  # noqa: BLE001 - the error belongs to the job's caller
                    conn.execute("ROLLBACK TO job")
                    results.append((done, None, exc))
                else:
                    results.append((done, value, None))
                conn.execute("RELEASE job")
            conn.execute("COMMIT")
        except (sqlite3.Error, OSError) as exc:
            log.error("store commit failed: %s", exc)
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            self._last_seq = seqs_before
            for _, done in batch:
                done(None, StoreError(f"commit failed: {exc}"))
            return
        for done, value, error in results:
            done(value, error)

    def _submit(self, work: Callable[[sqlite3.Connection], Any]) -> asyncio.Future[Any]:
        """Queue ``work`` for the writer; the future resolves after its transaction committed."""
        if self._closed:
            raise StoreError("the store is closed")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Any] = loop.create_future()

        def done(value: Any, error: BaseException | None) -> None:
            def settle() -> None:
                if future.done():
                    return
                if error is not None:
                    future.set_exception(error)
                else:
                    future.set_result(value)

            loop.call_soon_threadsafe(settle)

        self._jobs.put((work, done))
        return future

    def write_sync(self, work: Callable[[sqlite3.Connection], Any]) -> Any:
        """Run ``work`` in the writer thread and wait for its commit (for non-async callers)."""
        outcome: dict[str, Any] = {}
        finished = threading.Event()

        def done(value: Any, error: BaseException | None) -> None:
            outcome.update(value=value, error=error)
            finished.set()

        self._jobs.put((work, done))
        finished.wait()
        if outcome["error"] is not None:
            raise outcome["error"]
        return outcome["value"]

    def close(self, timeout_s: float = 30.0) -> None:
        """Finish queued writes; a writer stuck longer than ``timeout_s`` (a locked database) is
        left behind (a daemon thread) so that shutdown keeps its deadline."""
        if not self._closed:
            self._closed = True
            self._jobs.put(None)
            self._writer.join(timeout=timeout_s)
            if self._writer.is_alive():
                log.error("store writer still busy after %g s; leaving it (uncommitted writes are not acked)", timeout_s)

    # --- writes (run in the writer thread) ----------------------------------------------------

    def open_session(self, hello: Hello) -> asyncio.Future[int]:
        """Create the session, or resume it when ``hello`` is its owner with the same mode and
        geometry (else SessionOwnedError / SessionShapeError); resolves to its highest stored seq."""

        def work(conn: sqlite3.Connection) -> int:
            now = time.time()
            row = conn.execute(
                "SELECT device_id, stream_id, mode, sensor_w, sensor_h, fovea_h, fovea_w FROM sessions"
                " WHERE session_id = ?", (hello.session_id,),
            ).fetchone()
            if row is None:
                conn.execute(
                    "INSERT INTO sessions (session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w,"
                    " created_s, updated_s, stream_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (hello.session_id, hello.device_id, hello.mode, *hello.sensor, *hello.fovea, now, now,
                     hello.stream_id or ""),
                )
            else:
                check_owner(hello, row[0], row[1], row[2], (row[3], row[4]), (row[5], row[6]))
                conn.execute("UPDATE sessions SET updated_s = ? WHERE session_id = ?", (now, hello.session_id))
            return self._last_seq.setdefault(hello.session_id, -1)

        return self._submit(work)

    def _sequenced(
        self, session_id: str, seq: int, insert: Callable[[sqlite3.Connection], None]
    ) -> asyncio.Future[WriteResult]:
        def work(conn: sqlite3.Connection) -> WriteResult:
            last = self._last_seq.get(session_id)
            if last is None:
                raise StoreError(f"unknown session {session_id!r}")
            if seq <= last:
                return WriteResult(stored=False, last_seq=last)
            if seq != last + 1:  # an earlier message of the stream failed: never leave a hole
                raise StoreError(f"seq {seq} of session {session_id!r} does not follow the stored seq {last}")
            insert(conn)
            conn.execute(
                "UPDATE sessions SET last_seq = ?, updated_s = ? WHERE session_id = ?", (seq, time.time(), session_id)
            )
            self._last_seq[session_id] = seq
            return WriteResult(stored=True, last_seq=seq)

        return self._submit(work)

    def add_frame(self, session_id: str, frame: Frame) -> asyncio.Future[WriteResult]:
        row = (
            session_id, frame.seq, frame.frame_id, frame.t_us, *frame.origin, *frame.gaze_px, *frame.gaze_rad,
            frame.events_used, *frame.shape, frame.bits,
        )  # fmt: skip

        def insert(conn: sqlite3.Connection) -> None:
            conn.execute("INSERT INTO frames VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", row)

        return self._sequenced(session_id, frame.seq, insert)

    def add_page(self, session_id: str, page: Page) -> asyncio.Future[WriteResult]:
        folder = self.pages_dir / session_id
        path = folder / f"{page.seq}.png"

        def insert(conn: sqlite3.Connection) -> None:
            folder.mkdir(parents=True, exist_ok=True)
            _fsync_write(path, mask_to_png(page.mask()))
            conn.execute(
                "INSERT INTO pages VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (session_id, page.seq, page.page_id, page.t_us, *page.shape, str(path), json.dumps(page.lines)),
            )

        return self._sequenced(session_id, page.seq, insert)

    def add_gaze(self, session_id: str, gaze: Gaze) -> asyncio.Future[WriteResult]:
        samples = msgpack.packb({"t_us": gaze.t_us, "px": gaze.px})

        def insert(conn: sqlite3.Connection) -> None:
            conn.execute("INSERT INTO gaze VALUES (?, ?, ?)", (session_id, gaze.seq, samples))

        return self._sequenced(session_id, gaze.seq, insert)

    def delete_session(self, session_id: str) -> bool:
        """Remove a session with its frames, pages and files; False if it did not exist."""

        def work(conn: sqlite3.Connection) -> bool:
            for table in ("frames", "pages", "gaze"):
                conn.execute(f"DELETE FROM {table} WHERE session_id = ?", (session_id,))  # noqa: S608
            existed = conn.execute("DELETE FROM sessions WHERE session_id = ?", (session_id,)).rowcount > 0
            self._last_seq.pop(session_id, None)
            return existed

        existed = bool(self.write_sync(work))
        shutil.rmtree(self.pages_dir / session_id, ignore_errors=True)
        return existed

    # --- reads (any thread) -------------------------------------------------------------------

    def sessions(self) -> list[SessionInfo]:
        return self._session_rows("")

    def session(self, session_id: str) -> SessionInfo | None:
        rows = self._session_rows("WHERE s.session_id = ?", (session_id,))
        return rows[0] if rows else None

    def _session_rows(self, where: str, args: tuple[Any, ...] = ()) -> list[SessionInfo]:
        query = (
            "SELECT s.session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w, created_s, updated_s,"
            " last_seq, (SELECT COUNT(*) FROM frames f WHERE f.session_id = s.session_id),"
            " (SELECT COUNT(*) FROM pages p WHERE p.session_id = s.session_id)"
            f" FROM sessions s {where} ORDER BY updated_s DESC"
        )
        with self._reader() as conn:
            rows = conn.execute(query, args).fetchall()
        return [
            SessionInfo(r[0], r[1], r[2], (r[3], r[4]), (r[5], r[6]), r[7], r[8], r[9], r[10], r[11]) for r in rows
        ]

    def frames(self, session_id: str, limit: int) -> list[StoredFrame]:
        """The ``limit`` most recent frames of a session, oldest first."""
        with self._reader() as conn:
            rows = conn.execute(
                "SELECT seq, frame_id, t_us, x0, y0, gaze_u, gaze_v, rows, cols, bits FROM frames"
                " WHERE session_id = ? ORDER BY seq DESC LIMIT ?",
                (session_id, limit),
            ).fetchall()
        frames = []
        for seq, frame_id, t_us, x0, y0, u, v, rows_, cols, bits in reversed(rows):
            mask = unpack_bits((rows_, cols), bits)
            frames.append(StoredFrame(frame_id, t_us, mask, (x0, y0), (u, v), seq=seq))
        return frames

    def latest_page(self, session_id: str) -> StoredPage | None:
        with self._reader() as conn:
            row = conn.execute(
                "SELECT seq, page_id, t_us, png_path, lines FROM pages WHERE session_id = ? ORDER BY seq DESC LIMIT 1",
                (session_id,),
            ).fetchone()
        if row is None:
            return None
        lines = [tuple(box) for box in json.loads(row[4])]
        return StoredPage(row[0], row[1], row[2], Path(row[3]), lines)  # type: ignore[arg-type]

    def ping(self) -> bool:
        """True when the database answers (readiness)."""
        try:
            with self._reader() as conn:
                conn.execute("SELECT 1").fetchone()
        except sqlite3.Error:
            return False
        return self._writer.is_alive()
