"""The SQLite ``SessionStore``: WAL, ``synchronous=FULL``, group commit, versioned schema.

Layout under ``data_dir``::

    darkread.sqlite3            sessions, frames (mask bits + metadata), pages, gaze, page breaks
    pages/<session>/<seq>.png   page images (through ``FileBlobs``; rows hold only the key)

The schema version lives in ``PRAGMA user_version``; ``MIGRATIONS[i]`` takes a database from
version i to i + 1 (an SQL script, or a function for a step that must look first) and all
pending ones run at start-up, in one transaction each (the mechanism both backends share,
``migrations.py``). Duplicates
are found by the database: every sequenced table's primary key is (session_id, seq).
"""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from pathlib import Path
from typing import Any, TypeVar

import msgpack
import numpy as np

from darkread.core.image_codec import encode_png
from darkread.core.mask_bits import pack_bits, unpack_bits
from darkread.stitch.stitched_page import ink_mask_to_paper

from .blobs import BlobStore, FileBlobs, decode_mask_png, page_key
from .changes import ChangeFeed, Listener
from .migrations import Step, statements
from .migrations import migrate as run_migrations
from .records import (
    GazeRecord,
    PageBreak,
    PageRecord,
    SessionInfo,
    SessionSpec,
    StoredFrame,
    StoreError,
    UnknownSessionError,
    WriteResult,
    check_owner,
)
from .writer import GroupCommitWriter

log = logging.getLogger(__name__)
T = TypeVar("T")

MIGRATIONS: tuple[str | Callable[[sqlite3.Connection], object], ...] = (
    # 0 -> 1: the original schema (databases from before versioning already have it)
    """
    CREATE TABLE IF NOT EXISTS sessions (
        session_id TEXT PRIMARY KEY,
        device_id TEXT NOT NULL,
        mode TEXT NOT NULL,
        sensor_w INTEGER NOT NULL, sensor_h INTEGER NOT NULL,
        fovea_h INTEGER NOT NULL, fovea_w INTEGER NOT NULL,
        created_s REAL NOT NULL, updated_s REAL NOT NULL,
        last_seq INTEGER NOT NULL DEFAULT -1
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
    """,
    # 1 -> 2: page images behind the blob interface (a key relative to the data directory, the
    # same place the absolute paths pointed to), and the glasses' explicit page breaks
    """
    ALTER TABLE pages RENAME COLUMN png_path TO image_key;
    UPDATE pages SET image_key = 'pages/' || session_id || '/' || seq || '.png';
    CREATE TABLE page_breaks (
        session_id TEXT NOT NULL, seq INTEGER NOT NULL, t_us INTEGER NOT NULL,
        PRIMARY KEY (session_id, seq)
    );
    """,
    # 2 -> 3: sessions belong to the stream (spool, seq space) that opened them; databases the
    # unversioned store wrote since session ownership already have the column
    lambda conn: None
    if "stream_id" in {row[1] for row in conn.execute("PRAGMA table_info(sessions)")}
    else conn.execute("ALTER TABLE sessions ADD COLUMN stream_id TEXT NOT NULL DEFAULT ''"),
    # 3 -> 4: a fixation's fused view keeps its grey levels and the frames behind it (the stitcher
    # weighs it by them); binary frames have no levels and stand for one frame
    """
    ALTER TABLE frames ADD COLUMN levels BLOB;
    ALTER TABLE frames ADD COLUMN n_levels INTEGER NOT NULL DEFAULT 2;
    ALTER TABLE frames ADD COLUMN fused_frames INTEGER NOT NULL DEFAULT 1;
    """,
    # 4 -> 5: how far the scene had moved in the sensor at the frame (the head's motion, measured
    # on the glasses; the stitcher predicts from it); NULL for frames of glasses that do not say
    """
    ALTER TABLE frames ADD COLUMN scene_x REAL;
    ALTER TABLE frames ADD COLUMN scene_y REAL;
    """,
    # 5 -> 6: how much a live edge falling behind was giving up when it made the view (edge.load);
    # 0 for everything stored before the glasses said so
    "ALTER TABLE frames ADD COLUMN shed_level INTEGER NOT NULL DEFAULT 0",
    # 6 -> 7: the light the glasses measured at the page (lux; the cloud weighs a dim page's lines by
    # it); NULL for frames of glasses that did not say
    "ALTER TABLE frames ADD COLUMN light_lux REAL",
)
SCHEMA_VERSION = len(MIGRATIONS)
_SEQUENCED = ("frames", "pages", "gaze", "page_breaks")


class _SqliteSchema:
    """``SchemaTarget`` for SQLite: the version is ``PRAGMA user_version``."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def version(self) -> int:
        return int(self.conn.execute("PRAGMA user_version").fetchone()[0])

    def apply(self, step: Step, new_version: int) -> None:
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            if callable(step):
                step(self.conn)
            else:
                for statement in statements(step):
                    self.conn.execute(statement)
            self.conn.execute(f"PRAGMA user_version = {int(new_version)}")
            self.conn.execute("COMMIT")
        except sqlite3.Error:
            self.conn.execute("ROLLBACK")
            raise


def migrate(conn: sqlite3.Connection) -> int:
    """Apply every pending migration; returns the version the database was at before."""
    return run_migrations(_SqliteSchema(conn), MIGRATIONS, backend="SQLite")


class SqliteStore:
    """``SessionStore`` on one SQLite file. Writes go through one group-commit thread; reads run
    in worker threads on their own connections (WAL lets them run beside the writer)."""

    def __init__(self, data_dir: Path, *, blobs: BlobStore | None = None, read_threads: int = 4) -> None:
        self.data_dir = Path(data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.db_path = self.data_dir / "darkread.sqlite3"
        self.blobs = blobs or FileBlobs(self.data_dir)
        try:
            with closing(self._connect()) as conn:
                conn.execute("PRAGMA journal_mode=WAL")
                migrate(conn)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot open the database {self.db_path}: {exc}") from exc
        self._writer = GroupCommitWriter(self._connect)
        self._changes = ChangeFeed()
        # one read connection per worker thread, kept: opening one cost more than the query
        # (the live pages read every few frames)
        self._local = threading.local()
        self._readers: list[sqlite3.Connection] = []
        self._readers_lock = threading.Lock()
        # reads run on threads of their own: speech, OCR and other blocking work cannot queue them
        self._read_pool = ThreadPoolExecutor(read_threads, thread_name_prefix="darkread-store-read")

    def subscribe(self, listener: Listener) -> Callable[[], None]:
        return self._changes.subscribe(listener)

    def _connect(self) -> sqlite3.Connection:
        # Autocommit mode: transactions are explicit (BEGIN/COMMIT), so a savepoint never commits alone.
        conn = sqlite3.connect(self.db_path, timeout=30, check_same_thread=False, isolation_level=None)
        conn.execute("PRAGMA synchronous=FULL")  # a commit is on disk before we ack
        return conn

    def _reader(self) -> sqlite3.Connection:
        conn: sqlite3.Connection | None = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._local.conn = self._connect()
            with self._readers_lock:
                self._readers.append(conn)
        return conn

    def _drop_reader(self) -> None:
        conn = getattr(self._local, "conn", None)
        self._local.conn = None
        if conn is not None:
            with self._readers_lock:
                if conn in self._readers:
                    self._readers.remove(conn)
            conn.close()

    async def _read(self, query: Callable[[sqlite3.Connection], T]) -> T:
        def run() -> T:
            try:
                return query(self._reader())
            except sqlite3.Error as exc:
                self._drop_reader()  # the next read starts on a fresh connection
                raise StoreError(f"read failed: {exc}") from exc

        return await asyncio.get_running_loop().run_in_executor(self._read_pool, run)

    # --- writes -------------------------------------------------------------------------------

    async def open_session(self, spec: SessionSpec) -> int:
        def work(conn: sqlite3.Connection) -> int:
            now = time.time()
            row = conn.execute(
                "SELECT device_id, stream_id, mode, sensor_w, sensor_h, fovea_h, fovea_w, last_seq FROM sessions"
                " WHERE session_id = ?", (spec.session_id,),
            ).fetchone()  # fmt: skip
            if row is None:
                conn.execute(
                    "INSERT INTO sessions (session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w,"
                    " created_s, updated_s, stream_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (spec.session_id, spec.device_id, spec.mode, *spec.sensor, *spec.fovea, now, now, spec.stream_id),
                )
                return -1
            stored = SessionSpec(spec.session_id, row[0], row[2], (row[3], row[4]), (row[5], row[6]), row[1])
            check_owner(spec, stored)
            conn.execute("UPDATE sessions SET updated_s = ? WHERE session_id = ?", (now, spec.session_id))
            return int(row[7])

        return await self._writer.submit(work)

    async def _sequenced(self, session_id: str, seq: int, insert: Callable[[sqlite3.Connection], int]) -> WriteResult:
        """A write whose (session, seq) the database keeps once: ``insert`` returns its rowcount,
        0 when the key was already there (a resend)."""

        def work(conn: sqlite3.Connection) -> WriteResult:
            row = conn.execute("SELECT last_seq FROM sessions WHERE session_id = ?", (session_id,)).fetchone()
            if row is None:
                raise UnknownSessionError(f"unknown session {session_id!r}")
            if seq > int(row[0]) + 1:  # an earlier message of the stream failed: never leave a hole
                raise StoreError(f"seq {seq} of session {session_id!r} does not follow the stored seq {row[0]}")
            if insert(conn) == 0:
                if seq > int(row[0]):  # a row past the resume point: the database was changed behind our back
                    raise sqlite3.IntegrityError(
                        f"seq {seq} of session {session_id!r} is stored already, beyond its resume point {row[0]}"
                    )
                return WriteResult(stored=False, last_seq=int(row[0]))
            row = conn.execute(
                "UPDATE sessions SET last_seq = MAX(last_seq, ?), updated_s = ? WHERE session_id = ? RETURNING last_seq",
                (seq, time.time(), session_id),
            ).fetchone()
            if row is None:  # the savepoint rolls the insert back
                raise UnknownSessionError(f"unknown session {session_id!r}")
            return WriteResult(stored=True, last_seq=int(row[0]))

        result: WriteResult = await self._writer.submit(work)
        if result.stored:
            self._changes.publish(session_id, result.last_seq)
        return result

    async def add_frame(self, session_id: str, frame: StoredFrame) -> WriteResult:
        rows, cols = frame.mask.shape
        row = (
            session_id, frame.seq, frame.frame_id, frame.t_us, *frame.origin, *frame.gaze_px, *frame.gaze_rad,
            frame.events_used, rows, cols, pack_bits(frame.mask),
            None if frame.levels is None else frame.levels.tobytes(), frame.n_levels, frame.frames,
            *(frame.scene_px or (None, None)), frame.shed_level, frame.light_lux,
        )  # fmt: skip

        def insert(conn: sqlite3.Connection) -> int:
            sql = ("INSERT INTO frames (session_id, seq, frame_id, t_us, x0, y0, gaze_u, gaze_v, yaw, pitch, events_used,"
                   " rows, cols, bits, levels, n_levels, fused_frames, scene_x, scene_y, shed_level, light_lux)"
                   " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING")  # fmt: skip
            return conn.execute(sql, row).rowcount

        return await self._sequenced(session_id, frame.seq, insert)

    async def add_page(self, session_id: str, page: PageRecord) -> WriteResult:
        key = page_key(session_id, page.seq)
        rows, cols = page.mask.shape
        png = encode_png(ink_mask_to_paper(page.mask))

        def insert(conn: sqlite3.Connection) -> int:
            known = conn.execute("SELECT 1 FROM pages WHERE session_id = ? AND seq = ?", (session_id, page.seq))
            if known.fetchone() is not None:
                return 0  # a resend: the image is already there
            self.blobs.put(key, png)
            return conn.execute(
                "INSERT INTO pages VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (session_id, page.seq, page.page_id, page.t_us, rows, cols, key, json.dumps(page.lines)),
            ).rowcount

        return await self._sequenced(session_id, page.seq, insert)

    async def add_gaze(self, session_id: str, gaze: GazeRecord) -> WriteResult:
        samples = msgpack.packb({"t_us": gaze.t_us, "px": gaze.px})

        def insert(conn: sqlite3.Connection) -> int:
            sql = "INSERT INTO gaze VALUES (?, ?, ?) ON CONFLICT DO NOTHING"
            return conn.execute(sql, (session_id, gaze.seq, samples)).rowcount

        return await self._sequenced(session_id, gaze.seq, insert)

    async def add_page_break(self, session_id: str, mark: PageBreak) -> WriteResult:
        def insert(conn: sqlite3.Connection) -> int:
            sql = "INSERT INTO page_breaks VALUES (?, ?, ?) ON CONFLICT DO NOTHING"
            return conn.execute(sql, (session_id, mark.seq, mark.t_us)).rowcount

        return await self._sequenced(session_id, mark.seq, insert)

    async def delete_session(self, session_id: str) -> bool:
        def work(conn: sqlite3.Connection) -> bool:
            for table in _SEQUENCED:
                conn.execute(f"DELETE FROM {table} WHERE session_id = ?", (session_id,))
            return conn.execute("DELETE FROM sessions WHERE session_id = ?", (session_id,)).rowcount > 0

        existed = bool(await self._writer.submit(work))
        await asyncio.to_thread(self.blobs.delete_prefix, f"pages/{session_id}")
        return existed

    async def close(self, timeout_s: float = 30.0) -> None:
        await asyncio.to_thread(self._writer.close, timeout_s)
        self._read_pool.shutdown(wait=False, cancel_futures=True)
        with self._readers_lock:
            readers, self._readers = self._readers, []
        for conn in readers:
            conn.close()

    # --- reads --------------------------------------------------------------------------------

    async def sessions(self) -> list[SessionInfo]:
        return await self._read(lambda conn: _session_rows(conn, ""))

    async def session(self, session_id: str) -> SessionInfo | None:
        rows = await self._read(lambda conn: _session_rows(conn, "WHERE s.session_id = ?", (session_id,)))
        return rows[0] if rows else None

    async def frames(self, session_id: str, *, after_seq: int = -1, limit: int = 1000) -> list[StoredFrame]:
        def query(conn: sqlite3.Connection) -> list[tuple[Any, ...]]:
            return conn.execute(
                "SELECT seq, frame_id, t_us, x0, y0, gaze_u, gaze_v, yaw, pitch, events_used, rows, cols, bits,"
                " levels, n_levels, fused_frames, scene_x, scene_y, shed_level, light_lux FROM frames WHERE session_id = ? AND seq > ?"
                " ORDER BY seq LIMIT ?",
                (session_id, after_seq, limit),
            ).fetchall()

        frames = []
        for row in await self._read(query):
            seq, frame_id, t_us, x0, y0, u, v, yaw, pitch, used, rows, cols, bits, levels, n_levels, fused, sx, sy, shed, lux = row
            mask = unpack_bits((rows, cols), bits)
            grey = None if levels is None else np.frombuffer(levels, np.uint8).reshape(rows, cols)
            frames.append(StoredFrame(frame_id, t_us, mask, (x0, y0), (u, v), seq=seq, gaze_rad=(yaw, pitch), events_used=used,
                                      levels=grey, n_levels=n_levels, frames=fused,
                                      scene_px=None if sx is None else (sx, sy), shed_level=shed, light_lux=lux))  # fmt: skip
        return frames

    async def page_breaks(self, session_id: str) -> list[PageBreak]:
        rows = await self._read(
            lambda conn: conn.execute(
                "SELECT seq, t_us FROM page_breaks WHERE session_id = ? ORDER BY seq", (session_id,)
            ).fetchall()
        )
        return [PageBreak(int(seq), int(t_us)) for seq, t_us in rows]

    async def latest_page(self, session_id: str) -> PageRecord | None:
        def query(conn: sqlite3.Connection) -> PageRecord | None:
            row = conn.execute(
                "SELECT seq, page_id, t_us, image_key, lines FROM pages WHERE session_id = ?"
                " ORDER BY seq DESC LIMIT 1",
                (session_id,),
            ).fetchone()
            if row is None:
                return None
            seq, page_id, t_us, key, lines = row
            mask = decode_mask_png(self.blobs.get(key), key)
            return PageRecord(seq, page_id, t_us, mask, tuple(tuple(box) for box in json.loads(lines)))

        return await self._read(query)

    async def ping(self) -> bool:
        try:
            await self._read(lambda conn: conn.execute("SELECT 1").fetchone())
        except StoreError:
            return False
        return self._writer.alive


def _session_rows(conn: sqlite3.Connection, where: str, args: tuple[Any, ...] = ()) -> list[SessionInfo]:
    query = (
        "SELECT s.session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w, created_s, updated_s,"
        " last_seq, (SELECT COUNT(*) FROM frames f WHERE f.session_id = s.session_id),"
        " (SELECT COUNT(*) FROM pages p WHERE p.session_id = s.session_id)"
        f" FROM sessions s {where} ORDER BY updated_s DESC"
    )
    return [
        SessionInfo(r[0], r[1], r[2], (r[3], r[4]), (r[5], r[6]), r[7], r[8], r[9], r[10], r[11])
        for r in conn.execute(query, args).fetchall()
    ]
