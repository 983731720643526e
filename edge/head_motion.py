"""The head's motion known from outside the event stream.

The edge measures the head's motion from the events themselves: each window's smear by contrast
maximisation (``edge.deblur``) and the scene's drift across views by correlating count images
(``edge.scene_motion``). In the dark both see little, so a frame's strokes stay smeared and a view
may land where the page is not. An inertial sensor on the glasses, or for a synthetic recording
the simulator's own pose, knows the motion without looking at the events. A pipeline given a
``KnownHeadMotion`` takes both from it and measures neither; everything after (denoise, voxel
grid, network, fusion, stitching) runs as always. The lab drives a synthetic recording this way
(``darkread eval attribute``) to measure how much of a page's errors the head's motion causes.

The glasses' gyroscope (``edge.imu_motion``) knows the head's rotation, not the page's own motion
nor the head's translation, and not at all in a gap of its stream: it is a ``KnownHeadMotion`` that
is also a ``SmearPrior``. The deblur then searches only around its prediction (and where it has
none, as without it), and the event tracker keeps running beside it as the fallback and the check.
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


@runtime_checkable
class SmearPrior(Protocol):
    """A prediction of the deblur's smear that the events refine (``edge.deblur.smear_near``)."""

    smear_radius_px: float  # how far around the prediction the deblur searches

    def smear_prior(self, t_first_us: int, t_ref_us: int, centre_px: tuple[float, float]) -> tuple[float, float] | None:
        """The page's displacement at ``centre_px`` (sensor px) from ``t_first_us`` to ``t_ref_us``;
        None where it is not known (then the deblur searches as without it)."""
        ...

    def healthy(self, t_us: int) -> bool:
        """Whether the motion at ``t_us`` is known (else the edge falls back to the events)."""
        ...
