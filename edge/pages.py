"""Pages mode: frames (or, in the on-change mode, the fixations' views) are stitched on the glasses
and only the page goes up (``[uplink] mode = "pages"``).

The reconstruction thread adds each frame; the daemon's tick asks for the page every
``page_every_s`` and at shutdown. Stitching itself is the shared, pure stitcher; this module only
feeds it, guards it with a lock and turns its page into the wire message.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from darkread.core.frame_record import FrameRecord
from darkread.proto.messages import Page, pack_mask
from darkread.stitch import PageStitcher


class PageBuilder:
    """Stitches frames as they come (thread-safe) and makes a ``Page`` message when one is due."""

    def __init__(self, every_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.every_s = float(every_s)
        self._clock = clock
        self._stitcher = PageStitcher()
        self._lock = threading.Lock()
        self._last = clock()

    def add(self, frame: FrameRecord) -> None:
        """A frame (every-window) or a fixation's view (on-change: stitched as its frames, by its grey levels)."""
        with self._lock:
            self._stitcher.add(frame)  # a FrameResult or ViewRecord is the frame record the stitcher reads

    def due(self) -> bool:
        return self._clock() - self._last >= self.every_s

    def message(self, t_us: int, final: bool = False) -> Page | None:
        """The page so far as a wire message stamped ``t_us`` (None while it has no ink).

        ``final`` first closes the line being read, so its frames count too.
        """
        with self._lock:
            if final:
                self._stitcher.flush()
            page = self._stitcher.page()
        self._last = self._clock()
        if page.image.size == 0 or not page.image.any():
            return None
        shape, bits = pack_mask(page.image)
        lines = tuple((int(x0), int(y0), int(x1), int(y1)) for x0, y0, x1, y1 in page.lines)
        return Page(seq=0, page_id=0, t_us=int(t_us), shape=shape, bits=bits, lines=lines, enc="g4")  # v3: CCITT G4, the smallest
