"""The PostgreSQL ``SessionStore``: several cloud instances on one database.

Chosen by ``DARKREAD_DATABASE_URL=postgresql://...``. Everything a session has is in the
database (frames, gaze, page breaks, pages; page images as ``bytea`` behind ``BlobStore``), so
any instance serves any session and a frame resent to another instance after a failover is
stored once: every sequenced table's primary key is (session_id, seq) and inserts are
``ON CONFLICT DO NOTHING``; the rows an insert returns are the ones stored, the others are
duplicates, acknowledged as the SQLite backend does.

Ingest keeps SQLite's group commit: one writer task per instance takes every write waiting,
inserts each table's share with one ``INSERT ... SELECT FROM unnest(...)`` and advances each
session's ``last_seq`` in the same transaction. The sessions involved are locked in name order
first, so two instances writing the same sessions queue instead of deadlocking, and a session
deleted meanwhile is seen as unknown instead of failing the batch. The transaction also sends
``NOTIFY darkread_stored`` per session; every instance LISTENs and relays other instances'
commits to its subscribers (``subscribe``).

The schema is versioned in ``schema_version`` and migrated at start-up (``migrations.py``, the
mechanism SQLite uses too) under an advisory lock, so instances starting together migrate once.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
import uuid
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np
import psycopg
from psycopg import conninfo
from psycopg_pool import AsyncConnectionPool, ConnectionPool, PoolTimeout

from darkread.core.image_codec import encode_png
from darkread.core.mask_bits import pack_bits, unpack_bits
from darkread.stitch.stitched_page import ink_mask_to_paper

from .blobs import BlobStore, decode_mask_png, page_key
from .changes import ChangeFeed, Listener
from .migrations import Step, migrate, statements
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

log = logging.getLogger(__name__)

CHANNEL = "darkread_stored"
MIGRATION_LOCK = 0x6461726B72656164  # "darkread": the advisory lock instances migrate under
MAX_BATCH = 512
_DB_ERRORS = (psycopg.Error, PoolTimeout, OSError)

MIGRATIONS: tuple[str, ...] = (
    # 0 -> 1: sessions and their sequenced records; page images as blobs
    """
    CREATE TABLE sessions (
        session_id text PRIMARY KEY,
        device_id text NOT NULL,
        mode text NOT NULL,
        sensor_w integer NOT NULL, sensor_h integer NOT NULL,
        fovea_h integer NOT NULL, fovea_w integer NOT NULL,
        created_s double precision NOT NULL, updated_s double precision NOT NULL,
        last_seq bigint NOT NULL DEFAULT -1
    );
    CREATE INDEX sessions_by_activity ON sessions (updated_s DESC);
    CREATE TABLE frames (
        session_id text NOT NULL REFERENCES sessions ON DELETE CASCADE, seq bigint NOT NULL,
        frame_id bigint NOT NULL, t_us bigint NOT NULL,
        x0 integer NOT NULL, y0 integer NOT NULL,
        gaze_u double precision NOT NULL, gaze_v double precision NOT NULL,
        yaw double precision NOT NULL, pitch double precision NOT NULL,
        events_used integer NOT NULL, rows integer NOT NULL, cols integer NOT NULL, bits bytea NOT NULL,
        PRIMARY KEY (session_id, seq)
    );
    CREATE TABLE pages (
        session_id text NOT NULL REFERENCES sessions ON DELETE CASCADE, seq bigint NOT NULL,
        page_id bigint NOT NULL, t_us bigint NOT NULL, rows integer NOT NULL, cols integer NOT NULL,
        image_key text NOT NULL, lines jsonb NOT NULL,
        PRIMARY KEY (session_id, seq)
    );
    CREATE TABLE gaze (
        session_id text NOT NULL REFERENCES sessions ON DELETE CASCADE, seq bigint NOT NULL,
        samples bytea NOT NULL,
        PRIMARY KEY (session_id, seq)
    );
    CREATE TABLE page_breaks (
        session_id text NOT NULL REFERENCES sessions ON DELETE CASCADE, seq bigint NOT NULL,
        t_us bigint NOT NULL,
        PRIMARY KEY (session_id, seq)
    );
    CREATE TABLE blobs (
        key text PRIMARY KEY,
        data bytea NOT NULL
    )
    """,
    # 1 -> 2: a session belongs to the stream (spool, seq space) that opened it
    """
    ALTER TABLE sessions ADD COLUMN stream_id text NOT NULL DEFAULT ''
    """,
    # 2 -> 3: a fixation's fused view keeps its grey levels and the frames behind it (the stitcher
    # weighs it by them); binary frames have no levels and stand for one frame
    """
    ALTER TABLE frames ADD COLUMN levels bytea;
    ALTER TABLE frames ADD COLUMN n_levels integer NOT NULL DEFAULT 2;
    ALTER TABLE frames ADD COLUMN fused_frames integer NOT NULL DEFAULT 1
    """,
    # 3 -> 4: how far the scene had moved in the sensor at the frame (the head's motion, measured
    # on the glasses; the stitcher predicts from it); NULL for frames of glasses that do not say
    """
    ALTER TABLE frames ADD COLUMN scene_x float8;
    ALTER TABLE frames ADD COLUMN scene_y float8
    """,
    # 4 -> 5: how much a live edge falling behind was giving up when it made the view (edge.load);
    # 0 for everything stored before the glasses said so
    "ALTER TABLE frames ADD COLUMN shed_level integer NOT NULL DEFAULT 0",
    # 5 -> 6: the light the glasses measured at the page (lux; the cloud weighs a dim page's lines by
    # it); NULL for frames of glasses that did not say
    "ALTER TABLE frames ADD COLUMN light_lux float8",
)
SCHEMA_VERSION = len(MIGRATIONS)

# Each sequenced table: its columns (session_id and seq first) with the array type unnest takes.
_COLUMNS: dict[str, tuple[tuple[str, str], ...]] = {
    "frames": (
        ("session_id", "text"), ("seq", "bigint"), ("frame_id", "bigint"), ("t_us", "bigint"),
        ("x0", "integer"), ("y0", "integer"), ("gaze_u", "float8"), ("gaze_v", "float8"),
        ("yaw", "float8"), ("pitch", "float8"), ("events_used", "integer"),
        ("rows", "integer"), ("cols", "integer"), ("bits", "bytea"),
        ("levels", "bytea"), ("n_levels", "integer"), ("fused_frames", "integer"),
        ("scene_x", "float8"), ("scene_y", "float8"), ("shed_level", "integer"), ("light_lux", "float8"),
    ),
    "pages": (
        ("session_id", "text"), ("seq", "bigint"), ("page_id", "bigint"), ("t_us", "bigint"),
        ("rows", "integer"), ("cols", "integer"), ("image_key", "text"), ("lines", "jsonb"),
    ),
    "gaze": (("session_id", "text"), ("seq", "bigint"), ("samples", "bytea")),
    "page_breaks": (("session_id", "text"), ("seq", "bigint"), ("t_us", "bigint")),
}  # fmt: skip


def _insert_sql(table: str) -> str:
    """One statement for all of a batch's accepted rows of ``table``."""
    names = ", ".join(name for name, _ in _COLUMNS[table])
    arrays = ", ".join(f"%s::{kind}[]" for _, kind in _COLUMNS[table])
    return (
        f"INSERT INTO {table} ({names}) SELECT * FROM unnest({arrays})"  # names are ours
        " ON CONFLICT DO NOTHING RETURNING session_id, seq"
    )


_INSERT = {table: _insert_sql(table) for table in _COLUMNS}
_LOCK_SESSIONS = (
    "SELECT session_id, last_seq FROM sessions WHERE session_id = ANY(%s) ORDER BY session_id FOR NO KEY UPDATE"
)
# The batch's accepted seqs continue each session's stored ones, so its last_seq is the highest.
_ADVANCE = f"""
    WITH batch AS (SELECT * FROM unnest(%s::text[], %s::bigint[]) AS t(session_id, top))
    UPDATE sessions s SET last_seq = batch.top, updated_s = %s
    FROM batch WHERE s.session_id = batch.session_id AND s.last_seq < batch.top
    RETURNING s.session_id, s.last_seq, pg_notify('{CHANNEL}', %s || ' ' || s.last_seq || ' ' || s.session_id)::text
"""  # the channel is ours
_SESSIONS = """
    SELECT s.session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w, created_s, updated_s, last_seq,
        (SELECT count(*) FROM frames f WHERE f.session_id = s.session_id),
        (SELECT count(*) FROM pages p WHERE p.session_id = s.session_id)
    FROM sessions s {where} ORDER BY updated_s DESC
"""


def describe(url: str) -> str:
    """The database a URL names, without its password (for logs and errors)."""
    try:
        parts = conninfo.conninfo_to_dict(url)
    except psycopg.ProgrammingError:
        return "a PostgreSQL URL that cannot be parsed"
    return f"postgresql://{parts.get('user', '')}@{parts.get('host', 'localhost')}:{parts.get('port', 5432)}/{parts.get('dbname', '')}"


class _PostgresSchema:
    """``SchemaTarget`` for PostgreSQL: the version is the one row of ``schema_version``."""

    def __init__(self, conn: psycopg.Connection[Any]) -> None:
        self.conn = conn

    def version(self) -> int:
        self.conn.execute("CREATE TABLE IF NOT EXISTS schema_version (version integer NOT NULL)")
        row = self.conn.execute("SELECT max(version) FROM schema_version").fetchone()
        return int(row[0]) if row and row[0] is not None else 0

    def apply(self, step: Step, new_version: int) -> None:
        with self.conn.transaction():
            if callable(step):
                step(self.conn)
            else:
                for statement in statements(step):
                    self.conn.execute(statement)
            self.conn.execute("DELETE FROM schema_version")
            self.conn.execute("INSERT INTO schema_version (version) VALUES (%s)", (new_version,))


def migrate_database(url: str, scripts: Sequence[Step] = MIGRATIONS) -> int:
    """Bring the database at ``url`` to the current schema (blocking); the version it was at.
    StoreError names the database (never its password) when it cannot be reached or migrated."""
    try:
        with psycopg.connect(url, autocommit=True, connect_timeout=10) as conn:
            conn.execute("SELECT pg_advisory_lock(%s)", (MIGRATION_LOCK,))
            try:
                return migrate(_PostgresSchema(conn), scripts, backend="PostgreSQL")
            finally:
                conn.execute("SELECT pg_advisory_unlock(%s)", (MIGRATION_LOCK,))
    except _DB_ERRORS as exc:
        raise StoreError(f"cannot open the PostgreSQL database {describe(url)}: {_first_line(exc)}") from exc


class PgBlobs:
    """``BlobStore`` in the database's ``blobs`` table (blocking, on its own small pool)."""

    def __init__(self, pool: ConnectionPool[Any]) -> None:
        self.pool = pool

    def put(self, key: str, data: bytes) -> None:
        try:
            with self.pool.connection() as conn:
                conn.execute(
                    "INSERT INTO blobs (key, data) VALUES (%s, %s) ON CONFLICT (key) DO UPDATE SET data = excluded.data",
                    (key, data),
                )
        except _DB_ERRORS as exc:
            raise StoreError(f"blob {key!r} could not be stored: {exc}") from exc

    def get(self, key: str) -> bytes:
        try:
            with self.pool.connection() as conn:
                row = conn.execute("SELECT data FROM blobs WHERE key = %s", (key,)).fetchone()
        except _DB_ERRORS as exc:
            raise StoreError(f"blob {key!r} could not be read: {exc}") from exc
        if row is None:
            raise StoreError(f"blob {key!r} is missing")
        return bytes(row[0])

    def delete_prefix(self, prefix: str) -> None:
        try:
            with self.pool.connection() as conn:
                conn.execute("DELETE FROM blobs WHERE starts_with(key, %s)", (prefix + "/",))
        except _DB_ERRORS as exc:
            raise StoreError(f"blobs under {prefix!r} could not be deleted: {exc}") from exc


@dataclass
class _Insert:
    """One sequenced record waiting for the next batch."""

    table: str
    session_id: str
    seq: int
    row: tuple[Any, ...]  # the table's columns in ``_COLUMNS`` order
    done: asyncio.Future[WriteResult]


class _BatchWriter:
    """Group commit: one task commits every waiting insert in one transaction."""

    def __init__(self, url: str, instance_id: str, changes: ChangeFeed) -> None:
        self.url = url
        self._conn: psycopg.AsyncConnection[Any] | None = None
        self.instance_id = instance_id
        self.changes = changes
        self._queue: asyncio.Queue[_Insert | None] = asyncio.Queue()
        self._task = asyncio.create_task(self._run(), name="darkread-pg-writer")
        self.closed = False

    @property
    def alive(self) -> bool:
        return not self._task.done()

    def submit(self, table: str, session_id: str, seq: int, row: tuple[Any, ...]) -> asyncio.Future[WriteResult]:
        if self.closed:
            raise StoreError("the store is closed")
        job = _Insert(table, session_id, seq, row, asyncio.get_running_loop().create_future())
        self._queue.put_nowait(job)
        return job.done

    async def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._queue.put_nowait(None)
        await self._task

    async def _run(self) -> None:
        while (first := await self._queue.get()) is not None:
            batch = [first]
            stop = False
            while len(batch) < MAX_BATCH and not self._queue.empty():
                job = self._queue.get_nowait()
                if job is None:
                    stop = True
                    break
                batch.append(job)
            await self._commit(batch)
            if stop:
                break
        await self._drop_connection()

    async def _commit(self, batch: list[_Insert]) -> None:
        try:
            outcomes, last_seqs = await self._transaction(batch)
        except Exception as exc:  # whatever failed, the writer lives on and every caller hears of it
            log.error("PostgreSQL commit of %d records failed: %s", len(batch), _first_line(exc))
            for job in batch:
                if not job.done.done():
                    job.done.set_exception(StoreError(f"commit failed: {type(exc).__name__}: {_first_line(exc)}"))
            return
        advanced: dict[str, int] = {}
        for job, outcome in zip(batch, outcomes, strict=True):
            if job.done.done():  # the caller gave up (its connection closed)
                continue
            if isinstance(outcome, StoreError):
                job.done.set_exception(outcome)
                continue
            job.done.set_result(WriteResult(stored=outcome, last_seq=last_seqs[job.session_id]))
            if outcome:
                advanced[job.session_id] = last_seqs[job.session_id]
        for session_id, last_seq in advanced.items():
            self.changes.publish(session_id, last_seq)

    async def _transaction(self, batch: list[_Insert]) -> tuple[list[bool | StoreError], dict[str, int]]:
        """Commit the batch: per job stored (True), a duplicate (False) or its error; and each
        session's last_seq after it.

        Two round trips: the sessions' rows are locked and their last_seq read; then the accepted
        rows (each seq the one after its session's last, duplicates answered without a write, a
        gap refused so no frame is ever hidden behind the resume point), the last_seq advance and
        the commit go out pipelined."""
        sessions = sorted({job.session_id for job in batch})
        conn = await self._connection()
        try:
            async with conn.pipeline(), conn.transaction():
                locked = await conn.execute(_LOCK_SESSIONS, (sessions,))
                last_seqs = {session_id: int(last_seq) for session_id, last_seq in await locked.fetchall()}
                outcomes, accepted = _accept(batch, last_seqs)
                rows_of: dict[str, list[tuple[Any, ...]]] = defaultdict(list)
                for job in accepted:
                    rows_of[job.table].append(job.row)
                inserts = [
                    await conn.execute(_INSERT[table], [list(column) for column in zip(*rows, strict=True)])
                    for table, rows in rows_of.items()
                ]
                tops = {job.session_id: last_seqs[job.session_id] for job in accepted}
                if tops:
                    await conn.execute(_ADVANCE, (list(tops), list(tops.values()), time.time(), self.instance_id))
            inserted = {(table, session_id, int(seq)) for table, cursor in zip(rows_of, inserts, strict=True)
                        for session_id, seq in await cursor.fetchall()}  # fmt: skip
        except BaseException:
            await self._drop_connection()
            raise
        for index, job in enumerate(batch):
            if outcomes[index] is True and (job.table, job.session_id, job.seq) not in inserted:
                outcomes[index] = StoreError(  # the database was changed behind the resume point
                    f"seq {job.seq} of session {job.session_id!r} is stored already, beyond its resume point"
                )
        return outcomes, last_seqs

    async def _connection(self) -> psycopg.AsyncConnection[Any]:
        """The writer's own connection (no pool checkout per batch), reopened after a failure."""
        if self._conn is None or self._conn.closed:
            self._conn = await psycopg.AsyncConnection.connect(self.url, autocommit=True, connect_timeout=10)
        return self._conn

    async def _drop_connection(self) -> None:
        if self._conn is not None:
            await self._conn.close()
            self._conn = None


def _accept(batch: list[_Insert], last_seqs: dict[str, int]) -> tuple[list[bool | StoreError], list[_Insert]]:
    """Decide each job against its session's last stored seq, in batch order (``last_seqs`` is
    advanced in place): the next seq is stored, an older one is a duplicate, a later one a gap."""
    outcomes: list[bool | StoreError] = []
    accepted: list[_Insert] = []
    for job in batch:
        last = last_seqs.get(job.session_id)
        if last is None:
            outcomes.append(UnknownSessionError(f"unknown session {job.session_id!r}"))
        elif job.seq <= last:
            outcomes.append(False)
        elif job.seq == last + 1:
            last_seqs[job.session_id] = job.seq
            accepted.append(job)
            outcomes.append(True)
        else:  # an earlier message of the stream failed: never leave a hole
            outcomes.append(StoreError(f"seq {job.seq} of session {job.session_id!r} does not follow the stored seq {last}"))
    return outcomes, accepted


class PostgresStore:
    """``SessionStore`` on PostgreSQL. Open with ``await PostgresStore.open(url)``."""

    def __init__(
        self, url: str, pool: AsyncConnectionPool[Any], blob_pool: ConnectionPool[Any] | None, blobs: BlobStore
    ) -> None:
        self.url = url
        self.pool = pool
        self.blobs = blobs
        self.instance_id = uuid.uuid4().hex[:12]
        self._blob_pool = blob_pool
        self._changes = ChangeFeed()
        self._writer = _BatchWriter(url, self.instance_id, self._changes)
        self._listener = asyncio.create_task(self._listen(), name="darkread-pg-listen")
        self._closed = False

    @classmethod
    async def open(cls, url: str, *, blobs: BlobStore | None = None, max_connections: int = 8,
                   timeout_s: float = 3.0) -> PostgresStore:  # fmt: skip
        """Migrate the schema, open the connection pools and start the writer and the listener.
        ``timeout_s`` bounds a request's wait for a connection (the database down: a StoreError
        after that long, not psycopg's default 30 s)."""
        where = describe(url)
        before = await asyncio.to_thread(migrate_database, url)
        log.info("PostgreSQL store %s at schema version %d (was %d)", where, SCHEMA_VERSION, before)
        connect = {"autocommit": True, "connect_timeout": max(2, round(timeout_s))}
        pool: AsyncConnectionPool[Any] = AsyncConnectionPool(
            url, min_size=1, max_size=max_connections, open=False, kwargs=connect, timeout=timeout_s,
            check=AsyncConnectionPool.check_connection, name="darkread-pg",
        )  # fmt: skip
        blob_pool = None
        try:
            await pool.open(wait=True, timeout=15)
            if blobs is None:
                blob_pool = ConnectionPool(url, min_size=1, max_size=4, open=False, kwargs=connect, timeout=timeout_s,
                                           check=ConnectionPool.check_connection, name="darkread-pg-blobs")  # fmt: skip
                await asyncio.to_thread(blob_pool.open, True, 15)
                blobs = PgBlobs(blob_pool)
        except _DB_ERRORS as exc:
            await pool.close()
            raise StoreError(f"cannot connect to the PostgreSQL database {where}: {_first_line(exc)}") from exc
        return cls(url, pool, blob_pool, blobs)

    def subscribe(self, listener: Listener) -> Callable[[], None]:
        return self._changes.subscribe(listener)

    def _check_open(self) -> None:
        if self._closed:
            raise StoreError("the store is closed")

    async def _fetch(self, query: str, args: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        self._check_open()
        try:
            async with self.pool.connection() as conn:
                cursor = await conn.execute(query, args)
                return await cursor.fetchall()
        except _DB_ERRORS as exc:
            raise StoreError(f"read failed: {_first_line(exc)}") from exc

    # --- writes -------------------------------------------------------------------------------

    async def open_session(self, spec: SessionSpec) -> int:
        self._check_open()
        now = time.time()
        try:
            async with self.pool.connection() as conn:
                cursor = await conn.execute(
                    "INSERT INTO sessions (session_id, device_id, mode, sensor_w, sensor_h, fovea_h, fovea_w,"
                    " created_s, updated_s, stream_id) VALUES (%s, %s, %s, %s, %s, %s, %s, %s, %s, %s)"
                    " ON CONFLICT (session_id) DO NOTHING RETURNING last_seq",
                    (spec.session_id, spec.device_id, spec.mode, *spec.sensor, *spec.fovea, now, now, spec.stream_id),
                )
                if await cursor.fetchone() is not None:
                    return -1
                cursor = await conn.execute(
                    "UPDATE sessions SET updated_s = %s WHERE session_id = %s RETURNING device_id, stream_id, mode,"
                    " sensor_w, sensor_h, fovea_h, fovea_w, last_seq",
                    (now, spec.session_id),
                )
                row = await cursor.fetchone()
        except _DB_ERRORS as exc:
            raise StoreError(f"session {spec.session_id!r} could not be opened: {_first_line(exc)}") from exc
        if row is None:  # deleted between the two statements: open it afresh
            return await self.open_session(spec)
        stored = SessionSpec(spec.session_id, row[0], row[2], (row[3], row[4]), (row[5], row[6]), row[1])
        check_owner(spec, stored)
        return int(row[7])

    async def _sequenced(self, table: str, session_id: str, seq: int, row: tuple[Any, ...]) -> WriteResult:
        self._check_open()
        return await self._writer.submit(table, session_id, seq, (session_id, seq, *row))

    async def add_frame(self, session_id: str, frame: StoredFrame) -> WriteResult:
        rows, cols = frame.mask.shape
        bits = pack_bits(frame.mask)
        levels = None if frame.levels is None else frame.levels.tobytes()
        row = (frame.frame_id, frame.t_us, *frame.origin, *frame.gaze_px, *frame.gaze_rad, frame.events_used, rows, cols, bits,
               levels, frame.n_levels, frame.frames, *(frame.scene_px or (None, None)), frame.shed_level, frame.light_lux)  # fmt: skip
        return await self._sequenced("frames", session_id, frame.seq, row)

    async def add_page(self, session_id: str, page: PageRecord) -> WriteResult:
        self._check_open()
        key = page_key(session_id, page.seq)
        known = await self._fetch(
            "SELECT s.last_seq FROM pages p JOIN sessions s USING (session_id) WHERE p.session_id = %s AND p.seq = %s",
            (session_id, page.seq),
        )
        if known:  # a resend: the image is already there
            return WriteResult(stored=False, last_seq=int(known[0][0]))
        await asyncio.to_thread(self.blobs.put, key, encode_png(ink_mask_to_paper(page.mask)))
        rows, cols = page.mask.shape
        row = (page.page_id, page.t_us, rows, cols, key, json.dumps([list(box) for box in page.lines]))
        return await self._sequenced("pages", session_id, page.seq, row)

    async def add_gaze(self, session_id: str, gaze: GazeRecord) -> WriteResult:
        samples = msgpack.packb({"t_us": gaze.t_us, "px": gaze.px})
        return await self._sequenced("gaze", session_id, gaze.seq, (samples,))

    async def add_page_break(self, session_id: str, mark: PageBreak) -> WriteResult:
        return await self._sequenced("page_breaks", session_id, mark.seq, (mark.t_us,))

    async def delete_session(self, session_id: str) -> bool:
        self._check_open()
        try:
            async with self.pool.connection() as conn:
                cursor = await conn.execute("DELETE FROM sessions WHERE session_id = %s", (session_id,))
                existed = cursor.rowcount > 0
        except _DB_ERRORS as exc:
            raise StoreError(f"session {session_id!r} could not be deleted: {_first_line(exc)}") from exc
        await asyncio.to_thread(self.blobs.delete_prefix, f"pages/{session_id}")
        return existed

    async def close(self, timeout_s: float = 30.0) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            await asyncio.wait_for(self._writer.close(), timeout_s)
        except TimeoutError:
            log.warning("PostgreSQL writer did not finish within %.0f s; its pending writes are left behind", timeout_s)
        self._listener.cancel()
        if not (await asyncio.wait({self._listener}, timeout=5.0))[0]:
            log.warning("PostgreSQL LISTEN connection did not close within 5 s; left behind")
        await self.pool.close()
        if self._blob_pool is not None:
            await asyncio.to_thread(self._blob_pool.close)

    # --- reads --------------------------------------------------------------------------------

    async def sessions(self) -> list[SessionInfo]:
        return [_session_info(row) for row in await self._fetch(_SESSIONS.format(where=""))]

    async def session(self, session_id: str) -> SessionInfo | None:
        rows = await self._fetch(_SESSIONS.format(where="WHERE s.session_id = %s"), (session_id,))
        return _session_info(rows[0]) if rows else None

    async def frames(self, session_id: str, *, after_seq: int = -1, limit: int = 1000) -> list[StoredFrame]:
        rows = await self._fetch(
            "SELECT seq, frame_id, t_us, x0, y0, gaze_u, gaze_v, yaw, pitch, events_used, rows, cols, bits,"
            " levels, n_levels, fused_frames, scene_x, scene_y, shed_level, light_lux FROM frames WHERE session_id = %s AND seq > %s"
            " ORDER BY seq LIMIT %s",
            (session_id, after_seq, limit),
        )
        frames = []
        for seq, frame_id, t_us, x0, y0, u, v, yaw, pitch, used, n_rows, cols, bits, levels, n_levels, fused, sx, sy, shed, lux in rows:
            mask = unpack_bits((n_rows, cols), bits)
            grey = None if levels is None else np.frombuffer(bytes(levels), np.uint8).reshape(n_rows, cols)
            frames.append(StoredFrame(int(frame_id), int(t_us), mask, (x0, y0), (u, v), seq=int(seq), gaze_rad=(yaw, pitch),
                                      events_used=int(used), levels=grey, n_levels=int(n_levels),
                                      frames=int(fused), scene_px=None if sx is None else (sx, sy), shed_level=int(shed),
                                      light_lux=None if lux is None else float(lux)))  # fmt: skip
        return frames

    async def page_breaks(self, session_id: str) -> list[PageBreak]:
        rows = await self._fetch("SELECT seq, t_us FROM page_breaks WHERE session_id = %s ORDER BY seq", (session_id,))
        return [PageBreak(int(seq), int(t_us)) for seq, t_us in rows]

    async def latest_page(self, session_id: str) -> PageRecord | None:
        rows = await self._fetch(
            "SELECT seq, page_id, t_us, image_key, lines FROM pages WHERE session_id = %s ORDER BY seq DESC LIMIT 1",
            (session_id,),
        )
        if not rows:
            return None
        seq, page_id, t_us, key, lines = rows[0]
        mask = decode_mask_png(await asyncio.to_thread(self.blobs.get, key), key)
        return PageRecord(int(seq), int(page_id), int(t_us), mask, tuple(tuple(box) for box in lines))

    async def ping(self) -> bool:
        try:
            await self._fetch("SELECT 1")
        except StoreError:
            return False
        return self._writer.alive

    # --- other instances' commits ---------------------------------------------------------------

    async def _listen(self) -> None:
        """Relay NOTIFYs of other instances to this one's subscribers; reconnect when the link drops."""
        delay = 0.5
        while True:
            try:
                async with await psycopg.AsyncConnection.connect(self.url, autocommit=True) as conn:
                    await conn.execute(f"LISTEN {CHANNEL}")
                    delay = 0.5
                    async for note in conn.notifies():
                        self._relay(note.payload)
            except _DB_ERRORS as exc:
                log.warning("PostgreSQL LISTEN connection lost (%s); retrying in %.1f s", _first_line(exc), delay)
            await asyncio.sleep(delay)
            delay = min(10.0, delay * 2)

    def _relay(self, payload: str) -> None:
        instance, last_seq, session_id = payload.split(" ", 2)
        if instance != self.instance_id:  # our own commits were published when they were made
            self._changes.publish(session_id, int(last_seq))


def _session_info(r: tuple[Any, ...]) -> SessionInfo:
    return SessionInfo(r[0], r[1], r[2], (r[3], r[4]), (r[5], r[6]), r[7], r[8], int(r[9]), int(r[10]), int(r[11]))


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]
