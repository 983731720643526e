"""The head's motion known from outside the event stream.

The edge measures the head's motion from the events themselves: each window's smear by contrast
maximisation (``edge.deblur``) and the scene's drift across views by correlating count images
(``edge.scene_motion``). In the dark both see little, so a frame's strokes stay smeared and a view
may land where the page is not. An inertial sensor on the glasses, or for a synthetic recording
the simulator's own pose, knows the motion without looking at the events. A pipeline given a
``KnownHeadMotion`` takes both from it and measures neither; everything after (denoise, voxel
grid, network, fusion, stitching) runs as always. The lab drives a synthetic recording this way
(``darkread eval attribute``) to measure how much of a page's errors the head's motion causes.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from darkread.edge.events import Events


@runtime_checkable
class KnownHeadMotion(Protocol):
    """Where the page moves in the sensor, from a source other than the events."""

    def scene_px(self, t_us: int) -> tuple[float, float] | None:
        """How far the scene had moved in the sensor by ``t_us`` (sensor px, x right, y down) since
        the source's reference time; None where unknown. Only differences between times are used."""
        ...

    def warp(self, window: Events, origin: tuple[int, int], shape_hw: tuple[int, int]) -> Events:
        """``window``'s events moved to where their page points were at its newest event; those that
        leave the window at ``origin`` (``shape_hw``) are dropped."""
        ...
