"""Live pages: frames stitched into pages as they are stored, read line by line, pushed."""

from .paging import LivePage, Paginator, PagingConfig, RenderedPage
from .reading import LineReader, PageReading, ReadLine
from .sessions import Answer, LiveConfig, LivePages, PageSummary, SessionPages, page_event

__all__ = [
    "Answer",
    "LineReader",
    "LiveConfig",
    "LivePage",
    "LivePages",
    "PageReading",
    "PageSummary",
    "Paginator",
    "PagingConfig",
    "ReadLine",
    "RenderedPage",
    "SessionPages",
    "page_event",
]
