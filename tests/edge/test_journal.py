"""Journal log lines carry the syslog priority."""

from __future__ import annotations


def test_journal_format_carries_syslog_priorities() -> None:
    import logging

    from darkread.edge.journal import JournalFormatter, use_journal_format_if_under_systemd

    formatter = JournalFormatter()
    warning = logging.LogRecord("darkread.edge", logging.WARNING, __file__, 1, "spool at %d", (5,), None)
    assert formatter.format(warning) == "<4>darkread.edge: spool at 5"
    debug = logging.LogRecord("x", logging.DEBUG, __file__, 1, "a\nb", None, None)
    assert formatter.format(debug) == "<7>x: a\n<7>b"
    assert not use_journal_format_if_under_systemd({})
