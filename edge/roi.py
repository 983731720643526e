"""The sensor's region of interest: when the edge narrows the sensor to the window, and where.

With the ROI on, the sensor reads out only the view's window and a margin around it (the EVK4's
analog ROI: :meth:`~darkread.edge.sources.evk4.camera.Evk4Camera.set_roi`; a replay crops in its
decoder, :meth:`~darkread.edge.sources.replay.ReplaySource.set_roi`), so the events of the rest of
the sensor never cross USB nor get decoded. The price is the head's motion: measured from the
events (``edge.scene_motion``), it needs the whole sensor. So ``[pipeline] sensor_roi = "auto"``
(the default) narrows the sensor only while the head's motion is known from elsewhere and healthy
(``edge.head_motion``: an inertial sensor), and gives the whole sensor back to the event tracker
the moment it is not; ``"on"`` and ``"off"`` force it.

The window moves with the gaze with hysteresis (:func:`follow_window`): it is padded by a margin
and rewritten only once the wanted window leaves the padded one, so small eye movements cost no
register writes.
"""

from __future__ import annotations

from collections.abc import Callable

Rect = tuple[int, int, int, int]  # x0, y0, width, height

ROI_MODES = ("auto", "on", "off")  # ``[pipeline] sensor_roi``: the first is the default
ROI_FOLLOW_MARGIN_PX = 64  # slack around a wanted window so a reading saccade seldom needs a rewrite (docs/edge_cpu.md)


def rect_covers(outer: Rect, inner: Rect) -> bool:
    """Whether ``outer`` holds all of ``inner`` (both x0, y0, width, height)."""
    ox, oy, ow, oh = outer
    x0, y0, w, h = inner
    return ox <= x0 and oy <= y0 and x0 + w <= ox + ow and y0 + h <= oy + oh


NOT_YET = 1 << 62  # ``delivered_since`` of a window the sensor has not delivered yet (no event is that new)


def delivered_since(writes: list[tuple[int | None, Rect | None]], rect: Rect) -> int | None:
    """Since when every event of ``rect`` has been delivered, given the ROI writes (in effect from,
    the window or None for the whole sensor; oldest first; in effect None: not yet): where the
    oldest of the latest writes that all cover it took effect; ``NOT_YET`` while the newest, which does
    not cover it, has not; None when every write held covers it (as far as they tell, it always was).

    A newest write not yet in effect that covers ``rect``, over an ROI in effect that covers it too,
    changes nothing for it: its events go on being delivered whenever the switch happens, so the
    answer is the earlier writes' (and does not depend on how soon the source tells when the write
    took effect)."""
    since = None
    for k in range(len(writes) - 1, -1, -1):
        effective, roi = writes[k]
        if effective is None:  # not in effect yet (or moved on before it was)
            if k == len(writes) - 1 and not (_covers(roi, rect) and _covers(_in_effect(writes[:-1]), rect)):
                return NOT_YET
            continue
        if roi is not None and not rect_covers(roi, rect):
            return since if since is not None else effective
        since = effective
    return None


def _covers(roi: Rect | None, rect: Rect) -> bool:
    return roi is None or rect_covers(roi, rect)


def _in_effect(writes: list[tuple[int | None, Rect | None]]) -> Rect | None:
    """The ROI the newest write in effect set (None: the whole sensor, also before any write)."""
    return next((roi for effective, roi in reversed(writes) if effective is not None), None)


def follow_window(requested: Rect, current: Rect | None, margin: int, sensor_wh: tuple[int, int] = (1280, 720)) -> Rect | None:
    """The window to program for the wanted ``requested`` one, or None when ``current`` still covers it:
    the wanted window padded by ``margin`` on every side, clipped to the sensor."""
    x0, y0, w, h = requested
    if current is not None and rect_covers(current, requested):
        return None
    nx0, ny0 = max(0, x0 - margin), max(0, y0 - margin)
    nx1, ny1 = min(sensor_wh[0], x0 + w + margin), min(sensor_wh[1], y0 + h + margin)
    return nx0, ny0, nx1 - nx0, ny1 - ny0


def always(t_us: int) -> bool:
    """A known head motion that says nothing about its health is healthy at every time."""
    return True


def motion_healthy(known: object | None, t_us: int) -> bool:
    """Whether a known head motion is present and trustworthy at ``t_us``: its ``healthy(t_us)``
    when it has one (an inertial stream with a gap is not), else present means healthy."""
    if known is None:
        return False
    healthy: Callable[[int], bool] = getattr(known, "healthy", always)
    return bool(healthy(t_us))


def roi_wanted(mode: str, known: object | None, t_us: int, light_probe: bool = False) -> bool:
    """Whether the sensor should deliver only the window now (``mode`` is ``[pipeline] sensor_roi``):
    "auto" while the head's motion is known and healthy, except while the light is read
    (``light_probe``: through the ROI it cannot be, edge/bias_control.py)."""
    if mode == "on":
        return True
    if mode == "off":
        return False
    return not light_probe and motion_healthy(known, t_us)


def parse_roi_mode(raw: object) -> str:
    """``[pipeline] sensor_roi`` from TOML or the environment: "auto", "on", "off", or a boolean (on/off)."""
    if isinstance(raw, bool):
        return "on" if raw else "off"
    text = str(raw).strip().lower()
    if text in {"1", "true", "yes", "on"}:
        return "on"
    if text in {"0", "false", "no", "off"}:
        return "off"
    if text == "auto":
        return "auto"
    raise ValueError(f"config [pipeline] sensor_roi: cannot use {raw!r} (expected auto, on or off)")
