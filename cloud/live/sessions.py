"""Live pages of every session: each stored frame is stitched once, in a worker thread, into its
session's current page; questions read the page that is already there.

Per session one asyncio task pulls newly stored frames from the store (so a backlog costs no
memory and a restart rebuilds the pages the same way), and hands them in batches to the stitch
thread pool; the session's paginator is used by one thread at a time (``lock``). Rendering and
OCR run in their own small pool so a question does not queue behind other sessions' stitching,
and a question waiting for the page ends the batch being stitched after its current frame: it
waits for at most one frame, then for the frames stored before it only as long as
``catch_up_s``, and otherwise answers from the page as stitched so far (its version says how
far). While a question is being rendered and read, stitching of every session pauses (at most
``questions_first_s`` per batch, so it never starves): on a busy host the OCR of an answer
otherwise shared the cores with a stitching backlog that no answer waits for. A session that a
question is waiting for is the exception: its stitching is what that answer waits for, so it
goes on (with many wearers asking, some question is always being read, and every question then
waited its whole ``catch_up_s`` for stitching that had paused for the others). Sessions idle for
``live_idle_s`` are dropped from memory (rebuilt when asked again).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncGenerator, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from ..confidence import LineJudgement, load_model
from ..errors import NoPageError, StoreError
from ..ocr.base import OcrBackend
from ..store import PageBreak, SessionStore, StoredFrame
from .paging import LivePage, Paginator, PagingConfig, RenderedPage
from .reading import LineReader, PageReading

log = logging.getLogger(__name__)

RECANCEL_S = 0.1  # a session task that did not stop is cancelled again this often


@dataclass(frozen=True)
class LiveConfig:
    paging: PagingConfig = PagingConfig()
    batch_frames: int = 32  # frames stitched per turn (a question waits at most one batch)
    stitch_threads: int = 2
    ocr_threads: int = 1
    catch_up_s: float = 0.3  # a question first waits this long at most for frames stored before it
    questions_first_s: float = 0.5  # stitching pauses this long at most while a question is read (OCR gets the CPU)
    push_interval_s: float = 1.0  # live push: at most one page update per session this often
    live_idle_s: float = 300.0  # a session untouched this long leaves memory
    confidence_model: str | None = None  # the line-confidence model (JSON); None: the shipped one


@dataclass(frozen=True)
class PageSummary:
    index: int
    version: int
    first_seq: int
    last_seq: int
    started_by: str
    finished: bool


@dataclass(frozen=True)
class Answer:
    reading: PageReading
    page: RenderedPage
    frames_pending: bool  # frames stored before the question were not all stitched in time


class SessionPages:
    """The pages of one session, kept up to date with the store."""

    def __init__(self, session_id: str, owner: LivePages) -> None:
        self.session_id = session_id
        self.owner = owner
        self.paginator = Paginator(cfg=owner.cfg.paging)
        self.lock = asyncio.Lock()
        self.stitched_seq = -1
        self.idle = False
        self.last_used = time.monotonic()
        self.readers: dict[int, LineReader] = {}
        self.read_locks: dict[int, asyncio.Lock] = {}
        self.subscribers: set[asyncio.Queue[dict[str, Any]]] = set()
        self._breaks_applied = 0
        self._renders_waiting = 0  # questions waiting for ``lock``: the stitch thread stops its batch early
        self._catching_up = 0  # questions waiting for this session's stitching: it does not give way to others
        self._wanted = asyncio.Event()  # set while ``_catching_up``
        self._wake = asyncio.Event()
        self._wake.set()  # catch up with what is stored (after a restart: rebuild)
        self._progress = asyncio.Condition()
        self._last_push = 0.0
        self._pushing: asyncio.Task[None] | None = None
        self._later: asyncio.TimerHandle | None = None
        self._published: tuple[int, int] | None = None
        self.task = asyncio.create_task(self._run(), name=f"pages-{session_id}")

    def notify(self) -> None:
        """New frames or a page break were stored."""
        self.last_used = time.monotonic()
        self.idle = False
        self._wake.set()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        store, batch = self.owner.store, self.owner.cfg.batch_frames
        frames: list[StoredFrame] = []  # fetched, not yet stitched (a question cut the batch short)
        breaks: list[PageBreak] = []
        while True:
            await self._wake.wait()
            self._wake.clear()
            try:
                while True:
                    if not frames:
                        frames = await store.frames(self.session_id, after_seq=self.stitched_seq, limit=batch)
                        if not frames:
                            break
                        # read after the frames: the glasses send in seq order and commits keep
                        # it, so every break before these frames is visible now
                        breaks = await store.page_breaks(self.session_id)
                    await self.owner.questions_first(self._wanted)
                    async with self.lock:
                        done = await loop.run_in_executor(self.owner.stitch_pool, self._stitch, frames, breaks)
                    self.stitched_seq = frames[done - 1].seq
                    frames = frames[done:]
                    self._maybe_push()
                    async with self._progress:
                        self._progress.notify_all()
            except StoreError as exc:
                log.warning("session %s: pages wait for the store: %s", self.session_id, exc)
                frames = []
                await asyncio.sleep(1.0)
                self._wake.set()
                continue
            self.idle = not self._wake.is_set()
            async with self._progress:
                self._progress.notify_all()

    def _stitch(self, frames: list[StoredFrame], breaks: list[PageBreak]) -> int:
        """Worker thread: frames in order, each once, with the explicit breaks before it applied
        first; stops early (after at least one) when a question waits for the page. How many it took."""
        for done, frame in enumerate(frames, 1):
            while self._breaks_applied < len(breaks) and breaks[self._breaks_applied].seq < frame.seq:
                self.paginator.page_break()
                self._breaks_applied += 1
            try:
                self.paginator.add(frame)
            except ValueError as exc:  # a frame the stitcher cannot use (too small): left out, once
                log.warning("session %s: frame seq %d not stitched: %s", self.session_id, frame.seq, exc)
            if self._renders_waiting or (self.owner.reading and not self._catching_up):
                return done
        return len(frames)

    async def caught_up(self, timeout_s: float, upto_seq: int | None = None) -> bool:
        """Wait until every frame stored so far (or up to ``upto_seq``) is stitched, at most ``timeout_s``."""

        def reached() -> bool:
            return self.idle or (upto_seq is not None and self.stitched_seq >= upto_seq)

        self._catching_up += 1
        self._wanted.set()
        try:
            async with self._progress:
                try:
                    await asyncio.wait_for(self._progress.wait_for(reached), timeout_s)
                except TimeoutError:
                    return False
            return True
        finally:
            self._catching_up -= 1
            if not self._catching_up:
                self._wanted.clear()

    def summaries(self) -> list[PageSummary]:
        return [
            PageSummary(p.index, p.version, p.first_seq, p.last_seq, p.started_by, p.finished)
            for p in list(self.paginator.pages)
        ]

    def _page(self, index: int | None) -> LivePage:
        pages = self.paginator.pages
        if not pages:
            raise NoPageError(f"session {self.session_id!r} has no stitched frames yet")
        if index is None:
            return pages[-1]
        if not 0 <= index < len(pages):
            raise NoPageError(f"session {self.session_id!r} has pages 0-{len(pages) - 1}, not {index}")
        return pages[index]

    async def render(self, index: int | None = None) -> RenderedPage:
        self.last_used = time.monotonic()
        loop = asyncio.get_running_loop()
        self._renders_waiting += 1  # the stitch thread ends its batch after the current frame
        try:
            await self.lock.acquire()
        finally:
            self._renders_waiting -= 1
        try:
            page = self._page(index)
            rendered = await loop.run_in_executor(self.owner.ocr_pool, self.paginator.render, page)
        finally:
            self.lock.release()
        if rendered is None:
            raise NoPageError(f"page {page.index} of session {self.session_id!r} has no ink yet")
        return rendered

    async def read(self, index: int | None = None) -> tuple[PageReading, RenderedPage]:
        """The page's newest version read: only lines that changed go through OCR."""
        rendered = await self.render(index)
        reader = self.readers.setdefault(rendered.index, LineReader(self.owner.ocr, confidence=self.owner.confidence))
        lock = self.read_locks.setdefault(rendered.index, asyncio.Lock())
        async with lock:
            reading = await asyncio.get_running_loop().run_in_executor(self.owner.ocr_pool, reader.read, rendered)
        self._publish(reading)
        return reading, rendered

    # --- live push ----------------------------------------------------------------------------

    def subscribe(self) -> asyncio.Queue[dict[str, Any]]:
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=16)
        self.subscribers.add(queue)
        self._published = None  # the newcomer gets the page as it is now
        self.last_used = time.monotonic()
        self._maybe_push(force=True)
        return queue

    def unsubscribe(self, queue: asyncio.Queue[dict[str, Any]]) -> None:
        self.subscribers.discard(queue)

    def _maybe_push(self, force: bool = False) -> None:
        """Read and push the current page, at most once per ``push_interval_s``; an update that
        comes too soon is pushed when the interval is over, so the last version always goes out."""
        if not self.subscribers:
            return
        wait = self.owner.cfg.push_interval_s - (time.monotonic() - self._last_push)
        busy = self._pushing is not None and not self._pushing.done()
        if busy or (wait > 0 and not force):
            if self._later is None:
                self._later = asyncio.get_running_loop().call_later(max(wait, 0.05), self._push_later)
            return
        self._last_push = time.monotonic()
        self._pushing = asyncio.create_task(self._push())

    def _push_later(self) -> None:
        self._later = None
        self._maybe_push()

    async def _push(self) -> None:
        try:
            await self.read()
        except NoPageError:
            pass
        except Exception as exc:  # a failed push must not end the session's pages
            log.warning("session %s: live update failed: %s", self.session_id, exc)

    def _publish(self, reading: PageReading) -> None:
        if self._published == (reading.index, reading.version):
            return
        self._published = (reading.index, reading.version)
        event = page_event(reading)
        for queue in list(self.subscribers):
            if queue.full():  # a slow client skips versions, never blocks the others
                with contextlib.suppress(asyncio.QueueEmpty):
                    queue.get_nowait()
            queue.put_nowait(event)

    async def close(self, timeout_s: float = 5.0) -> None:
        """Stop the session's task. A cancellation can be lost (psycopg's pool loses one now and
        then while handing out a connection: seen in 3 of 5 PostgreSQL ingest runs), so it is sent
        again every ``RECANCEL_S``; a task still running after ``timeout_s`` is left behind, so
        one stuck session cannot hold the whole shutdown."""
        if self._pushing is not None:
            self._pushing.cancel()
        if self._later is not None:
            self._later.cancel()
        deadline = time.monotonic() + timeout_s
        while not self.task.done() and (left := deadline - time.monotonic()) > 0:
            self.task.cancel()
            await asyncio.wait({self.task}, timeout=min(RECANCEL_S, left))
        if not self.task.done():
            log.warning("session %s: its page task did not stop within %.1f s; left behind", self.session_id, timeout_s)
        elif not self.task.cancelled() and (exc := self.task.exception()) is not None:
            log.warning("session %s: its page task had stopped: %s", self.session_id, exc)


def _judged(judgement: LineJudgement | None) -> dict[str, Any]:
    if judgement is None:
        return {"status": "read"}
    return {"status": judgement.status, "confidence": judgement.confidence, "reasons": list(judgement.reasons)}


def page_event(reading: PageReading) -> dict[str, Any]:
    return {
        "page": reading.index,
        "version": reading.version,
        "lines": [{"text": line.text, "box": list(line.box), **_judged(line.judgement)} for line in reading.lines],
        "text": reading.text,
    }


class LivePages:
    """Every session's live pages, the worker pools, and the idle sweep."""

    def __init__(self, store: SessionStore, ocr: OcrBackend, cfg: LiveConfig = LiveConfig()) -> None:
        self.store = store
        self.ocr = ocr
        self.confidence = load_model(cfg.confidence_model)
        self.cfg = cfg
        self.stitch_pool = ThreadPoolExecutor(cfg.stitch_threads, thread_name_prefix="darkread-stitch")
        self.ocr_pool = ThreadPoolExecutor(cfg.ocr_threads, thread_name_prefix="darkread-ocr")
        self._sessions: dict[str, SessionPages] = {}
        self.reading = 0  # questions being rendered and read now (stitching gives way to them)
        self._no_reading = asyncio.Event()
        self._no_reading.set()

    def get(self, session_id: str) -> SessionPages:
        """The session's pages, started (and rebuilt from the store) on first use."""
        pages = self._sessions.get(session_id)
        if pages is None:
            pages = self._sessions[session_id] = SessionPages(session_id, self)
        return pages

    def notify(self, session_id: str) -> None:
        self.get(session_id).notify()

    def wake(self, session_id: str) -> None:
        """Frames were stored by another instance (shared database): catch up if the session is live here."""
        pages = self._sessions.get(session_id)
        if pages is not None:
            pages.notify()

    @property
    def live_sessions(self) -> int:
        return len(self._sessions)

    async def ask(self, session_id: str, index: int | None = None, upto_seq: int | None = None) -> Answer:
        """Read the page; first wait (``catch_up_s`` at most) for the frames up to ``upto_seq``
        (the last seq stored when the question came; None: everything stored)."""
        pages = self.get(session_id)
        started = time.perf_counter()
        done = await pages.caught_up(self.cfg.catch_up_s, upto_seq)
        waited = time.perf_counter()
        with self.answering():
            reading, rendered = await pages.read(index)
        log.info(
            "session %s: page %d v%d, waited %.0f ms for stitching, rendered and read %d of %d lines in %.0f ms",
            session_id, reading.index, reading.version, (waited - started) * 1000, reading.lines_read,
            len(rendered.bands), (time.perf_counter() - waited) * 1000,
        )  # fmt: skip
        return Answer(reading, rendered, frames_pending=not done)

    @contextlib.contextmanager
    def answering(self) -> Iterator[None]:
        """A question is being rendered and read: stitching gives way meanwhile."""
        self.reading += 1
        self._no_reading.clear()
        try:
            yield
        finally:
            self.reading -= 1
            if not self.reading:
                self._no_reading.set()

    async def questions_first(self, wanted: asyncio.Event | None = None) -> None:
        """Before a stitch batch: wait while questions are being read (``questions_first_s`` at
        most), unless ``wanted`` is or becomes set (a question waits for this very session)."""
        if not self.reading or (wanted is not None and wanted.is_set()):
            return
        waits = [asyncio.ensure_future(self._no_reading.wait())]
        if wanted is not None:
            waits.append(asyncio.ensure_future(wanted.wait()))
        try:
            await asyncio.wait(waits, timeout=self.cfg.questions_first_s, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for wait in waits:
                wait.cancel()

    async def events(self, session_id: str) -> AsyncGenerator[dict[str, Any], None]:
        pages = self.get(session_id)
        queue = pages.subscribe()
        try:
            while True:
                yield await queue.get()
        finally:
            pages.unsubscribe(queue)

    async def forget(self, session_id: str) -> None:
        pages = self._sessions.pop(session_id, None)
        if pages is not None:
            await pages.close()

    async def sweep(self) -> list[str]:
        """Drop sessions untouched for ``live_idle_s`` and nobody listening from memory."""
        now = time.monotonic()
        idle = [
            sid for sid, p in self._sessions.items()
            if not p.subscribers and p.idle and now - p.last_used > self.cfg.live_idle_s
        ]  # fmt: skip
        for sid in idle:
            await self.forget(sid)
        return idle

    async def close(self, timeout_s: float = 5.0) -> None:
        """Stop every session (together, ``timeout_s`` at most) and the pools (the batch being
        stitched and the page being read finish first, ``timeout_s`` at most, off the event loop)."""
        sessions = [self._sessions.pop(sid) for sid in list(self._sessions)]
        await asyncio.gather(*(pages.close(timeout_s) for pages in sessions))
        for what, pool in (("stitching", self.stitch_pool), ("reading", self.ocr_pool)):
            stopping = asyncio.ensure_future(asyncio.to_thread(pool.shutdown, wait=True, cancel_futures=True))
            if not (await asyncio.wait({stopping}, timeout=timeout_s))[0]:
                log.warning("%s still busy after %.1f s; shutdown goes on", what, timeout_s)
