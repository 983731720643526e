"""What a camera with its ROI set delivers, so the bench times the ROI mode on that stream alone.

A replay with the ROI set still walks every word of a whole-sensor file (its decoder skips the words
outside the ROI, but reads them); a camera with the ROI set never sends them. So the wearable's mode
is measured in two passes:

1. the edge replays the whole-sensor recording in its ROI mode once, and the replay's deliveries
   are kept (``record_deliveries``): each chunk holds the events inside the ROI in force when the
   decoder read it, exactly what would have crossed USB, and every ROI the edge programmed is logged
   with the event time it was written at;
2. ``write_delivered`` makes those events a recording (the project's EVT3 writer, the other files
   copied), and the edge replays it in the same mode, its ROI writes logged but not applied again
   (``replay_as_delivered``): the file already is what the sensor sent, and cropping it a second
   time at this replay's own chunk boundaries would drop events the first pass delivered.

The two passes see the same events, so they make the same frames and views (the bench checks it).
The replay is wrapped from outside (its ``start`` and ``set_roi`` on the instance): the product's
replay has no business recording itself.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, Events, concat_events
from darkread.edge.io.raw import write_raw
from darkread.edge.io.raw_header import read_raw_header
from darkread.edge.roi import NOT_YET, Rect
from darkread.edge.sources.base import EventSink
from darkread.edge.sources.replay import ReplaySource


@dataclass
class Deliveries:
    """What a replay handed the edge (chunks, in order) and the ROI writes: (newest event time
    delivered when written, the ROI; the whole sensor is (0, 0, width, height))."""

    chunks: list[Events] = field(default_factory=list)
    roi_writes: list[tuple[int, Rect]] = field(default_factory=list)
    keep_events: bool = True
    # each write's first delivered event (the replay's ``roi_since_us``): the edge takes a window's
    # events from there on, so the second pass must be told the first's
    effective: dict[int, int] = field(default_factory=dict)  # write index -> event time

    @property
    def events(self) -> Events:
        """The chunks as one array (whole records, ``EVENT_CD_DTYPE``'s padding kept)."""
        return concat_events(self.chunks) if self.chunks else np.empty(0, EVENT_CD_DTYPE)

    def newest_t(self) -> int:
        return int(self.chunks[-1]["t"][-1]) if self.chunks else -1


class _AsDelivered(ReplaySource):
    """A replay of what a first pass delivered: its ROI writes are not applied, and each takes effect
    where it did in the first pass (``roi_since_us``). It still says which ROI the edge programmed
    (``roi``), as the first pass did: whoever asks what the sensor delivers (the light estimate counts
    the background only while it is whole) must hear the same in both passes."""

    delivered_since: int | None = None
    programmed: Rect | None = None

    @property
    def roi_since_us(self) -> int | None:
        return self.delivered_since

    @property
    def roi(self) -> Rect:
        return self.programmed or (0, 0, self.width, self.height)


def _wrap(source: ReplaySource, apply_roi: bool, keep_events: bool, effective: dict[int, int] | None = None) -> Deliveries:
    log = Deliveries(keep_events=keep_events)
    start, set_roi = source.start, source.set_roi
    if not apply_roi:
        source.__class__ = _AsDelivered

    def start_tapped(sink: EventSink) -> None:
        def deliver(events: Events) -> None:
            last = len(log.roi_writes) - 1
            if last >= 0 and last not in log.effective:  # the first chunk decoded under the last write
                since = source.roi_since_us
                log.effective[last] = int(events["t"][0]) if since is None else int(since)
            if log.keep_events:
                log.chunks.append(events.copy())
            else:  # only the newest time is needed (for the ROI log)
                log.chunks[:] = [events[-1:].copy()]
            sink(events)

        start(deliver)

    def set_roi_logged(x0: int, y0: int, width: int, height: int) -> None:
        rect = (int(x0), int(y0), int(width), int(height))
        log.roi_writes.append((log.newest_t(), rect))
        if apply_roi:
            set_roi(x0, y0, width, height)
        elif isinstance(source, _AsDelivered):
            source.programmed = rect
            k = len(log.roi_writes) - 1
            # (a write the first pass never saw take effect stays out of effect here too)
            source.delivered_since = (effective or {}).get(k, NOT_YET)

    source.start = start_tapped  # type: ignore[method-assign]
    source.set_roi = set_roi_logged  # type: ignore[method-assign]
    return log


def record_deliveries(source: ReplaySource) -> Deliveries:
    """Pass 1 (before the source starts): keep every chunk ``source`` delivers and log its ROI writes."""
    return _wrap(source, apply_roi=True, keep_events=True)


def replay_as_delivered(source: ReplaySource, first: Deliveries) -> Deliveries:
    """Pass 2 (before the source starts): the file holds what the sensor delivered through its ROI,
    so the edge's ROI writes are logged and not applied, each in effect from where it was in the
    ``first`` pass."""
    return _wrap(source, apply_roi=False, keep_events=False, effective=first.effective)


def write_delivered(recording: Path, deliveries: Deliveries, out: Path) -> Path:
    """``recording`` with its events.raw replaced by the delivered events (its other files copied;
    ``meta.json``'s event count is the delivered one, and it names what the file is)."""
    out.mkdir(parents=True, exist_ok=True)
    for item in recording.iterdir():
        if item.is_file() and item.name not in ("events.raw", "meta.json"):
            shutil.copy(item, out / item.name)
    events = deliveries.events
    header = read_raw_header(recording / "events.raw")
    write_raw(out / "events.raw", events, width=header.width, height=header.height)
    meta = json.loads((recording / "meta.json").read_text()) if (recording / "meta.json").is_file() else {}
    meta["event_count"] = int(events.shape[0])
    meta["delivered_through_roi"] = {"from": recording.name, "roi_writes": len(deliveries.roi_writes)}
    (out / "meta.json").write_text(json.dumps(meta, indent=2))
    return out
