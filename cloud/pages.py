"""The page a question is asked about: the glasses' own page, or the session's frames stitched."""

from __future__ import annotations

import asyncio
import threading
from collections import OrderedDict, deque
from dataclasses import dataclass

import numpy as np

from .store import FrameRecord, SessionStore

Box = tuple[int, int, int, int]


class NoPageError(Exception):
    """The session has nothing to read yet (no frames or pages stored)."""


class StitchUnavailableError(Exception):
    """The stitcher (``darkread.edge.stitch``) is not installed in this deployment."""


@dataclass(frozen=True)
class PageImage:
    page_id: str  # "page-<page_id>" for glasses pages, "frames-<first seq>-<last seq>" for stitched ones
    image: np.ndarray  # uint8 black text (0) on white (255); stitched pages carry grey shades
    lines: list[Box]


def stitch_frames(frames: list[FrameRecord], page_id: str) -> PageImage:
    """Stored frames -> the stitched page (the same stitcher the glasses run)."""
    try:
        from darkread.edge.stitch import StitchFrame, stitch_page
    except ImportError as exc:
        raise StitchUnavailableError(
            "page stitching (darkread.edge.stitch) is not installed; install darkread with its core package"
        ) from exc
    stitch_frames_ = [StitchFrame(f.frame_id, f.t_us, f.mask, f.origin, f.gaze_px) for f in frames]
    page = stitch_page(stitch_frames_)
    if page.image.size == 0:
        raise NoPageError("the frames stored so far did not stitch into a page (blank or unregistered)")
    lines: list[Box] = [(int(x0), int(y0), int(x1), int(y1)) for x0, y0, x1, y1 in page.lines]
    # OCR reads the alpha-averaged page with its grey shades: thresholding bold reconstructions
    # first costs several points of CER (e/o, a/o, i/l merge); glasses pages arrive binary anyway.
    return PageImage(page_id, page.to_grey(), lines)


class PageAssembler:
    """Builds the current page of a session, caching stitched pages by their last frame seq."""

    def __init__(self, store: SessionStore, max_frames: int, cache_size: int = 16) -> None:
        self.store = store
        self.max_frames = max_frames
        self._cache: OrderedDict[tuple[str, int], PageImage] = OrderedDict()
        self._cache_size = cache_size
        self._lock = threading.Lock()

    async def current_page(self, session_id: str, mode: str, last_seq: int) -> PageImage:
        """The page now; stitching runs in a worker thread."""
        if mode == "pages":
            stored = await self.store.latest_page(session_id)
            if stored is None:
                raise NoPageError(f"session {session_id!r} has not sent a page yet")
            return PageImage(f"page-{stored.page_id}", np.where(stored.mask != 0, 0, 255).astype(np.uint8), list(stored.lines))
        key = (session_id, last_seq)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        recent: deque[FrameRecord] = deque(maxlen=self.max_frames)
        while chunk := await self.store.frames(session_id, after_seq=recent[-1].seq if recent else -1):
            recent.extend(chunk)
        frames = list(recent)
        if not frames:
            raise NoPageError(f"session {session_id!r} has not sent any frames yet")
        page = await asyncio.to_thread(stitch_frames, frames, f"frames-{frames[0].seq}-{frames[-1].seq}")
        with self._lock:
            self._cache[key] = page
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return page

    def forget(self, session_id: str) -> None:
        with self._lock:
            for key in [k for k in self._cache if k[0] == session_id]:
                del self._cache[key]
