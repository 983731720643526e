"""Versioned schemas, one mechanism for every backend.

A backend's schema is a tuple of steps: ``steps[i]`` takes a database from version i to i + 1,
an SQL script (statements split on ``;``) or a function of the connection for a step that must
look first. At start-up ``migrate`` reads the version the database is at, refuses one from a
newer darkread, and runs every pending step in its own transaction, recording the new version
inside that transaction so a failed step leaves the previous version.
Where the version lives and how a transaction is opened is the backend's ``SchemaTarget``
(SQLite: ``PRAGMA user_version``; PostgreSQL: a ``schema_version`` table under an advisory
lock, so instances starting together migrate once).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from .records import StoreError

log = logging.getLogger(__name__)

Step = str | Callable[[Any], object]  # an SQL script, or a function of the backend's connection


class SchemaTarget(Protocol):
    """The few things ``migrate`` needs from a database connection."""

    def version(self) -> int:
        """The schema version the database is at (0 for an empty database)."""

    def apply(self, step: Step, new_version: int) -> None:
        """Run ``step`` and record ``new_version``, all in one transaction (rolled back on error)."""


def statements(script: str) -> list[str]:
    """A migration script as its statements (no statement of ours contains a literal ``;``)."""
    return [s.strip() for s in script.split(";") if s.strip()]


def migrate(target: SchemaTarget, steps: Sequence[Step], *, backend: str) -> int:
    """Bring the database to ``len(steps)``; returns the version it was at before."""
    latest = len(steps)
    before = target.version()
    if before > latest:
        raise StoreError(
            f"the {backend} database is at schema version {before}; this darkread knows up to {latest} (upgrade darkread)"
        )
    for version in range(before, latest):
        try:
            target.apply(steps[version], version + 1)
        except StoreError:
            raise
        except Exception as exc:  # driver errors of either backend become one StoreError
            raise StoreError(f"{backend} schema migration {version} -> {version + 1} failed: {exc}") from exc
        log.info("%s store schema migrated to version %d", backend, version + 1)
    return before
