"""The store's change feed: "session S now has everything up to seq N", to whoever listens.

Live pages and event streams subscribe instead of polling. A backend publishes after each
commit; PostgreSQL also relays the commits of every other instance on the same database
(LISTEN/NOTIFY), so a subscriber on any instance hears of frames streamed to any other.
Listeners run on the store's event loop and must not block (they set an event, queue a wake-up).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

log = logging.getLogger(__name__)

Listener = Callable[[str, int], None]  # (session_id, last stored seq)


class ChangeFeed:
    def __init__(self) -> None:
        self._listeners: list[Listener] = []

    def subscribe(self, listener: Listener) -> Callable[[], None]:
        """Call ``listener(session_id, last_seq)`` after every commit; returns the unsubscribe."""
        self._listeners.append(listener)

        def unsubscribe() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)

        return unsubscribe

    def publish(self, session_id: str, last_seq: int) -> None:
        for listener in list(self._listeners):
            try:
                listener(session_id, last_seq)
            except Exception:  # one broken listener must not stop ingest
                log.exception("store change listener failed for session %s", session_id)
