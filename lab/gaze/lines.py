"""Which printed line each fixation of a reading belongs to, as the stitcher decides it.

The stitcher's gaze logic, applied to fixations instead of frames: return sweeps split the reading
into read lines (``LineSegmenter``: a long jump left, not up), and the read lines are placed on the
text's lines by the monotone assignment of their mean gaze rows (``assign_lines``: a sweep goes
down one line, staying or skipping costs a pitch of gaze error, a jump back up the page restarts
the order). The text's lines come from the page (here: the passage layout).

``eyekit_lines`` runs the drift-correction methods of Carr et al. (2022) as the maintained
``eyekit`` package implements them. On the 24 adult readers of their data the stitcher's logic
places 95.2 % of fixations on their gold line, eyekit's ``slice`` 99.4 % and the vote of
``slice``, ``warp`` and ``stretch`` 99.6 %, so fixation files are assigned by that vote
(``DEFAULT_METHOD``; docs/gaze.md has the table, with tracker noise too).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from darkread.core.frame_record import FrameRecord
from darkread.stitch.config import StitchConfig
from darkread.stitch.page import assign_lines
from darkread.stitch.segment import segment_lines

EYEKIT_METHODS: tuple[str, ...] = ("chain", "cluster", "merge", "regress", "segment", "slice", "split", "stretch", "warp")
STITCHER = "stitcher"  # the stitcher's own logic (return sweeps + monotone assignment)
DEFAULT_METHOD: tuple[str, ...] = ("slice", "warp", "stretch")  # eyekit's vote of three methods
_BLANK = np.zeros((1, 1), dtype=np.uint8)  # fixations carry no image


def segment_config(line_pitch_px: float, cfg: StitchConfig = StitchConfig()) -> StitchConfig:
    """The stitcher's sweep thresholds for a page of this line pitch (a sweep may rise ~2 pitches
    of gaze error; the defaults assume ~30 px, the sensor's pitch at x-height 10 px)."""
    return replace(cfg, sweep_max_rise_px=2.0 * float(line_pitch_px))


def read_lines(x: np.ndarray, y: np.ndarray, cfg: StitchConfig = StitchConfig()) -> np.ndarray:
    """Read-line number of every fixation (0, 1, ... in reading order), split at return sweeps."""
    # one fixation, one sample of the track (a second apart: the segmenter thins only denser frames)
    frames = [FrameRecord(i, i * 1_000_000, _BLANK, (0, 0), (float(xi), float(yi))) for i, (xi, yi) in enumerate(zip(x, y))]
    out = np.empty(len(frames), dtype=np.int64)
    for k, line in enumerate(segment_lines(frames, cfg)):
        for f in line:
            out[f.frame_id] = k
    return out


def product_lines(x: np.ndarray, y: np.ndarray, line_y: np.ndarray, line_pitch_px: float) -> np.ndarray:
    """Printed-line index of every fixation (-1: off the text block), by the stitcher's logic."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.size == 0:
        return np.zeros(0, dtype=np.int64)
    segs = read_lines(x, y, segment_config(line_pitch_px))
    rows = [float(np.mean(y[segs == k])) for k in range(int(segs.max()) + 1)]
    bands = np.asarray(assign_lines(rows, [float(v) for v in line_y]), dtype=np.int64)
    out = bands[segs]
    off = (y < line_y[0] - 1.5 * line_pitch_px) | (y > line_y[-1] + 1.5 * line_pitch_px)
    return np.where(off, -1, out)


def eyekit_lines(x: np.ndarray, y: np.ndarray, start_ms: np.ndarray, end_ms: np.ndarray, text_block,
                 method: str | tuple[str, ...] | list[str]) -> np.ndarray:
    """Printed-line index of every fixation by one of eyekit's ``snap_to_lines`` methods (or the
    vote of three or more)."""
    import eyekit

    if not isinstance(method, str):
        method = list(method)
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64)
    seq = eyekit.FixationSequence([[float(a), float(b), int(s), int(e)] for a, b, s, e in zip(x, y, start_ms, end_ms)])
    seq.snap_to_lines(text_block, method=method)
    snapped = np.array([f.y for f in seq], dtype=np.float64)
    mid = np.asarray(text_block.midlines, dtype=np.float64)
    return np.abs(snapped[:, None] - mid[None, :]).argmin(axis=1).astype(np.int64)


def eyekit_text_block(lines: list[str], x0: float, y0: float, font_size: float, line_height: float, font_face: str = "Courier New"):
    import eyekit

    return eyekit.TextBlock(lines, position=(x0, y0), font_face=font_face, font_size=font_size, line_height=line_height)


def fixation_lines(x: np.ndarray, y: np.ndarray, start_ms: np.ndarray, end_ms: np.ndarray, passage,
                   method: str | tuple[str, ...] = DEFAULT_METHOD) -> np.ndarray:
    """Printed-line index of every fixation over a monospaced ``passage`` (``human.Passage``);
    -1 for a fixation the method puts on no line. ``method``: an eyekit method, a tuple of them
    (vote) or ``STITCHER``."""
    if method == STITCHER:
        return product_lines(x, y, passage.line_y, passage.line_h)
    block = eyekit_text_block(passage.lines, passage.x0, passage.y0, passage.font_size, passage.line_h)
    return eyekit_lines(x, y, start_ms, end_ms, block, method)


def eyekit_available() -> str | None:
    """None when eyekit (and the cairo library under it) imports, else why not."""
    try:
        import eyekit  # noqa: F401  # imported only to learn whether it is installed
    except (ImportError, OSError) as exc:
        return f"eyekit is not usable here ({exc}); install darkread[gaze] (and libcairo2)"
    return None
