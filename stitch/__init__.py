"""Hierarchical page stitching of foveated binary frames (pure: numpy + OpenCV; the glasses and the
cloud both import it).

frames -> lines (return sweeps in the gaze track, ``segment``) -> per-line strips registered by
correlation (``register``) and accumulated with an alpha channel and an improvement mask
(``strip``) -> KLT de-warp against the page above (``dewarp``) -> placement and threshold
(``page``), driven incrementally by ``PageStitcher`` (``stitcher``).
"""

from darkread.stitch.config import StitchConfig
from darkread.stitch.page import naive_page
from darkread.stitch.register import Registration, register_frame
from darkread.stitch.segment import LineSegmenter, segment_lines
from darkread.stitch.stitched_page import StitchedPage
from darkread.stitch.stitcher import PageStitcher, stitch_page

__all__ = [
    "LineSegmenter",
    "PageStitcher",
    "Registration",
    "StitchConfig",
    "StitchedPage",
    "naive_page",
    "register_frame",
    "segment_lines",
    "stitch_page",
]
