"""A window's isolated events dropped in dim light: shot noise out, strokes kept.

In the dark most of a window's events are shot noise: a pixel fires now and then whatever it
sees, independently of its neighbours, while a moving edge fires along a line. At 10 and 5 lux
many of a window's events have no other event on the 8 pixels around them over the window's
span; in bright light few do (docs/denoise.md has the shares). A network given only the events with a neighbour
sees the strokes against a clean background instead of a snow of dots (what a background-activity
filter does in event cameras, here over the window as a whole: its events are already moved back
along the head's motion by ``edge.deblur``, so an edge's events lie together).

A pixel's own repeats do not count as its neighbours: a hot or flickering pixel fires alone,
however often. The filter runs only on a noisy window (``min_isolated_share`` of its events
isolated): in bright light the few isolated events are the fine ends of strokes, and taking them
out of small letters cost more than it gave.

What it gains and costs, measured on the evaluation suite read end to end with and without it,
is in docs/denoise.md. Pure: numpy and OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from darkread.edge.events import Events


@dataclass(frozen=True)
class DenoiseConfig:
    enabled: bool = True
    min_neighbours: int = 1  # an event with fewer other events on the 8 pixels around it is noise ...
    min_isolated_share: float = 0.1  # ... dropped only from a window where at least this share is (dim light)

    def __post_init__(self) -> None:
        if self.min_neighbours < 1 or not 0.0 <= self.min_isolated_share <= 1.0:
            raise ValueError(f"DenoiseConfig: min_neighbours >= 1 and min_isolated_share in [0, 1] expected: {self}")


def isolated(window: Events, origin: tuple[int, int], shape_hw: tuple[int, int], min_neighbours: int = 1) -> np.ndarray:
    """Which of ``window``'s events (all inside the window at ``origin`` of ``shape_hw``) have fewer
    than ``min_neighbours`` events on the 8 pixels around their own (bool [n])."""
    h, w = shape_hw
    x = np.clip(window["x"].astype(np.intp) - origin[0], 0, w - 1)
    y = np.clip(window["y"].astype(np.intp) - origin[1], 0, h - 1)
    pixel = y * w + x
    counts = np.bincount(pixel, minlength=h * w).astype(np.float32)
    around = cv2.boxFilter(counts.reshape(h, w), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT).ravel()
    return (around[pixel] - counts[pixel]) < min_neighbours


def drop_isolated(window: Events, origin: tuple[int, int], shape_hw: tuple[int, int],
                  cfg: DenoiseConfig = DenoiseConfig()) -> Events:
    """``window`` without its isolated events when it is noisy (see the module), else as it was."""
    if not cfg.enabled or window.shape[0] == 0:
        return window
    alone = isolated(window, origin, shape_hw, cfg.min_neighbours)
    if alone.mean() < cfg.min_isolated_share:
        return window
    return window[~alone]
