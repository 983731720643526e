"""Log lines for the systemd journal: the syslog priority as a ``<N>`` prefix on every line."""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping


class JournalFormatter(logging.Formatter):
    """``<priority>name: message`` lines: journald reads the syslog priority, adds time and unit."""

    PRIORITIES = ((logging.CRITICAL, 2), (logging.ERROR, 3), (logging.WARNING, 4), (logging.INFO, 6))

    def format(self, record: logging.LogRecord) -> str:
        priority = next((p for level, p in self.PRIORITIES if record.levelno >= level), 7)
        text = f"{record.name}: {record.getMessage()}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return "\n".join(f"<{priority}>{line}" for line in text.splitlines())


def use_journal_format_if_under_systemd(environ: Mapping[str, str] | None = None) -> bool:
    """Switch the root handlers to :class:`JournalFormatter` when stderr goes to the journal."""
    if not (os.environ if environ is None else environ).get("JOURNAL_STREAM"):
        return False
    for handler in logging.getLogger().handlers:
        handler.setFormatter(JournalFormatter())
    return True
