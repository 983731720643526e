"""Test data factories (import as ``from factories import ...``)."""

from __future__ import annotations

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE


def random_events(
    n: int, width: int = 1280, height: int = 720, t0: int = 0, rate_hz: float = 1e6, seed: int = 0
) -> np.ndarray:
    """Random time-sorted events (a tonic-style factory)."""
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=EVENT_CD_DTYPE)
    ev["x"] = rng.integers(0, width, n)
    ev["y"] = rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    ev["t"] = t0 + np.sort(rng.integers(0, max(1, int(n / rate_hz * 1e6)), n))
    return ev


def pangram_session(motion: str, lux: float = 1000.0):
    """A short synthetic reading of a two-line pangram (seed 5, DejaVu Sans, x-height 11 px)."""
    from darkread.models.synth.recording import RecordingSpec
    from darkread.models.synth.rgb_camera import session_for

    spec = RecordingSpec(lux=lux, motion=motion, kind="pangram", seconds=2.0, seed=5, font="DejaVu Sans",
                         xheight_px=11.0, n_lines=2, line_chars=24)
    return session_for(spec)


def under_light(session, lux: float):
    """The same session lit by ``lux``."""
    from dataclasses import replace

    return replace(session, scene=replace(session.scene, lux=lux))
