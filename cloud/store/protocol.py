"""``SessionStore``: everything the cloud keeps about a session, as one async interface.

Ingest, page assembly and the REST routes talk only to this protocol, in domain records
(``records.py``). A write returns once its record is durable (the stream acks after it), and a
record whose (session, seq) is already stored is a duplicate: acknowledged, not stored again.
SQLite (``sqlite.py``) is the first backend; a second one only has to pass
``tests/cloud/store/test_contract.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from .records import GazeRecord, PageBreak, PageRecord, SessionInfo, SessionSpec, StoredFrame, WriteResult


class SessionStore(Protocol):
    async def open_session(self, spec: SessionSpec) -> int:
        """Create the session, or resume it when ``spec`` is its owner (same device and stream) with
        the same mode and geometry (else SessionOwnedError / SessionShapeError); its highest stored
        seq (-1 if none)."""

    async def add_frame(self, session_id: str, frame: StoredFrame) -> WriteResult:
        """Seqs are contiguous: a seq past the stored one + 1 is a StoreError, never a hole."""

    async def add_page(self, session_id: str, page: PageRecord) -> WriteResult: ...

    async def add_gaze(self, session_id: str, gaze: GazeRecord) -> WriteResult: ...

    async def add_page_break(self, session_id: str, mark: PageBreak) -> WriteResult:
        """The glasses said the wearer moved to other text: frames after ``mark.seq`` start a page."""

    async def session(self, session_id: str) -> SessionInfo | None: ...

    async def sessions(self) -> list[SessionInfo]:
        """Every session, most recently active first."""

    async def frames(self, session_id: str, *, after_seq: int = -1, limit: int = 1000) -> list[StoredFrame]:
        """Up to ``limit`` frames with seq > ``after_seq``, oldest first (page through long sessions)."""

    async def page_breaks(self, session_id: str) -> list[PageBreak]:
        """The session's explicit page breaks, in seq order."""

    async def latest_page(self, session_id: str) -> PageRecord | None:
        """The most recent page sent by the glasses, with its image."""

    async def delete_session(self, session_id: str) -> bool:
        """Remove the session with everything stored for it; False if it did not exist."""

    def subscribe(self, listener: Callable[[str, int], None]) -> Callable[[], None]:
        """Call ``listener(session_id, last_seq)`` on the event loop after records of a session are
        committed, by this process or (a shared database) any other instance; returns the unsubscribe."""

    async def ping(self) -> bool:
        """True when the backend answers (readiness)."""

    async def close(self, timeout_s: float = 30.0) -> None:
        """Finish pending writes (at most ``timeout_s``) and release the backend; later writes raise StoreError."""
