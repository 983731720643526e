"""Group commit for SQLite: one writer thread, one transaction per batch of waiting writes.

Every write waiting when a transaction starts goes into the same commit, so many concurrent
streams share each fsync while every caller still learns of its own commit. A write that fails
rolls back only its own savepoint and reports its error to its own caller.
"""

from __future__ import annotations

import asyncio
import logging
import queue
import sqlite3
import threading
from collections.abc import Callable
from typing import Any, TypeVar

from ..errors import StoreError

log = logging.getLogger(__name__)

T = TypeVar("T")
Work = Callable[[sqlite3.Connection], Any]
_Done = Callable[[Any, BaseException | None], None]
MAX_BATCH = 512


class GroupCommitWriter:
    """Runs ``work(conn)`` jobs in one thread on one connection, committing them in groups."""

    def __init__(self, connect: Callable[[], sqlite3.Connection], name: str = "darkread-store-writer") -> None:
        self._connect = connect
        self._jobs: queue.Queue[tuple[Work, _Done] | None] = queue.Queue()
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def submit(self, work: Callable[[sqlite3.Connection], T]) -> asyncio.Future[T]:
        """Queue ``work``; the future (of the running loop) resolves after its transaction committed."""
        if self._closed:
            raise StoreError("the store is closed")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()

        def settle(value: Any, error: BaseException | None) -> None:
            if future.done():
                return
            if error is not None:
                future.set_exception(error)
            else:
                future.set_result(value)

        def done(value: Any, error: BaseException | None) -> None:
            try:
                loop.call_soon_threadsafe(settle, value, error)
            except RuntimeError:  # the caller's loop is gone; nobody waits for the answer
                pass

        self._jobs.put((work, done))
        return future

    def close(self, timeout_s: float = 30.0) -> None:
        """Let queued writes commit, then stop the thread; a writer stuck longer than
        ``timeout_s`` (a locked database) is left behind (a daemon thread) so shutdown keeps its
        deadline."""
        if not self._closed:
            self._closed = True
            self._jobs.put(None)
            self._thread.join(timeout=timeout_s)
            if self._thread.is_alive():
                log.error("store writer still busy after %g s; leaving it (uncommitted writes are not acked)", timeout_s)

    def _loop(self) -> None:
        conn = self._connect()
        try:
            while True:
                job = self._jobs.get()
                if job is None:
                    return
                batch = [job]
                while len(batch) < MAX_BATCH:  # take everything already waiting
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

    @staticmethod
    def _run_batch(conn: sqlite3.Connection, batch: list[tuple[Work, _Done]]) -> None:
        results: list[tuple[_Done, Any, BaseException | None]] = []
        try:
            conn.execute("BEGIN IMMEDIATE")
            for work, done in batch:
                conn.execute("SAVEPOINT job")
                try:
                    value = work(conn)
                except Exception as exc:  # the error belongs to the job's caller
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
            for _, done in batch:
                done(None, StoreError(f"commit failed: {exc}"))
            return
        for done, value, error in results:
            done(value, error)
