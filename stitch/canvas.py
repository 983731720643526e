"""A float canvas in page coordinates that grows as frames land outside it."""

from __future__ import annotations

import numpy as np

_GROW_STEP = 256  # grow by whole blocks so a line of frames does not reallocate every time


class Canvas:
    """Named float32 layers sharing one extent; (x, y) page coordinates may be negative."""

    def __init__(self, layers: tuple[str, ...]) -> None:
        self.layers: dict[str, np.ndarray] = {name: np.zeros((0, 0), np.float32) for name in layers}
        self.x0 = 0
        self.y0 = 0
        self.empty = True

    def fork(self) -> Canvas:
        """An independent copy (the layers copied, nothing else to share)."""
        twin = Canvas(())
        twin.layers = {name: layer.copy() for name, layer in self.layers.items()}
        twin.x0, twin.y0, twin.empty = self.x0, self.y0, self.empty
        return twin

    @property
    def shape(self) -> tuple[int, int]:
        return next(iter(self.layers.values())).shape

    @property
    def box(self) -> tuple[int, int, int, int]:
        h, w = self.shape
        return self.x0, self.y0, self.x0 + w, self.y0 + h

    def ensure(self, x0: int, y0: int, x1: int, y1: int) -> None:
        """Make the box [x0, x1) x [y0, y1) part of the canvas."""
        if self.empty:
            self.x0, self.y0 = x0 - _GROW_STEP // 2, y0 - _GROW_STEP // 2
            h, w = y1 - y0 + _GROW_STEP, x1 - x0 + _GROW_STEP
            self.layers = {k: np.zeros((h, w), np.float32) for k in self.layers}
            self.empty = False
            return
        cx0, cy0, cx1, cy1 = self.box
        if x0 >= cx0 and y0 >= cy0 and x1 <= cx1 and y1 <= cy1:
            return
        left = max(0, cx0 - x0 + _GROW_STEP // 2) if x0 < cx0 else 0
        top = max(0, cy0 - y0 + _GROW_STEP // 2) if y0 < cy0 else 0
        right = max(0, x1 - cx1 + _GROW_STEP // 2) if x1 > cx1 else 0
        bottom = max(0, y1 - cy1 + _GROW_STEP // 2) if y1 > cy1 else 0
        self.layers = {k: np.pad(v, ((top, bottom), (left, right))) for k, v in self.layers.items()}
        self.x0 -= left
        self.y0 -= top

    def view(self, name: str, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Writable view of a box that must lie inside the canvas (call ``ensure`` first)."""
        return self.layers[name][y0 - self.y0 : y1 - self.y0, x0 - self.x0 : x1 - self.x0]

    def crop(self, name: str, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Copy of a box; zeros where the canvas does not reach."""
        out = np.zeros((y1 - y0, x1 - x0), np.float32)
        if self.empty:
            return out
        cx0, cy0, cx1, cy1 = self.box
        ix0, iy0, ix1, iy1 = max(x0, cx0), max(y0, cy0), min(x1, cx1), min(y1, cy1)
        if ix0 < ix1 and iy0 < iy1:
            out[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0] = self.view(name, ix0, iy0, ix1, iy1)
        return out
