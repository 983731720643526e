"""Event arrays: OpenEB's CD layout, so arrays pass to Metavision and tonic without copying.

``EVENT_CD_DTYPE`` is byte-identical to OpenEB's ``EventCD`` (x u2 @0, y u2 @2, p i2 @4, t i8 @8,
itemsize 16). ``p`` is 1 for ON (brightness up) and 0 for OFF; ``t`` is in microseconds.
External-trigger events use OpenEB's ``EventExtTrigger`` layout (p i2 @0, t i8 @8, id i2 @16).

The layout has two padding bytes, and numpy copies a structured dtype with padding field by
field: a copy, a concatenation or a boolean selection of event arrays is 5-40x slower than the
same bytes moved as opaque 16-byte records (measured: 2.7 ms against 71 µs to concatenate two
43k-event chunks). Hot paths move events with :func:`concat_events`, :func:`copy_events` and
:func:`select_events`, which do exactly that.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

EVENT_CD_DTYPE = np.dtype(
    {"names": ["x", "y", "p", "t"], "formats": ["<u2", "<u2", "<i2", "<i8"], "offsets": [0, 2, 4, 8], "itemsize": 16}
)
TRIGGER_DTYPE = np.dtype(
    {"names": ["p", "t", "id"], "formats": ["<i2", "<i8", "<i2"], "offsets": [0, 8, 16], "itemsize": 24}
)

Events = npt.NDArray[np.void]
"""A 1-D structured array of ``EVENT_CD_DTYPE``, sorted by ``t``."""

_RECORD = np.dtype((np.void, EVENT_CD_DTYPE.itemsize))  # one event as opaque bytes


def concat_events(parts: list[Events] | tuple[Events, ...]) -> Events:
    """``np.concatenate`` of event arrays, moved as whole records."""
    return np.concatenate([np.asarray(part, dtype=EVENT_CD_DTYPE).view(_RECORD) for part in parts]).view(EVENT_CD_DTYPE)


def copy_events(events: Events) -> Events:
    """A copy of ``events`` (``events.copy()``), moved as whole records."""
    if events.dtype != EVENT_CD_DTYPE:  # another layout (numpy packs fields in some operations): as it is
        return events.copy()
    return events.view(_RECORD).copy().view(EVENT_CD_DTYPE)


def select_events(events: Events, which: np.ndarray) -> Events:
    """``events[which]`` for a boolean mask or an index array, moved as whole records."""
    if events.dtype != EVENT_CD_DTYPE:
        return events[which]
    return events.view(_RECORD)[which].view(EVENT_CD_DTYPE)


def empty_events(n: int = 0) -> Events:
    """A zero-filled event array; ``n == 0`` is the canonical empty window (never ``None``)."""
    return np.zeros(n, dtype=EVENT_CD_DTYPE)


def empty_triggers(n: int = 0) -> npt.NDArray[np.void]:
    return np.zeros(n, dtype=TRIGGER_DTYPE)


def make_events(
    x: npt.ArrayLike, y: npt.ArrayLike, p: npt.ArrayLike, t: npt.ArrayLike
) -> Events:
    """Build an event array from columns (broadcast to one length)."""
    x, y, p, t = np.broadcast_arrays(np.asarray(x), np.asarray(y), np.asarray(p), np.asarray(t))
    events = empty_events(x.shape[0] if x.ndim else 1)
    events["x"], events["y"], events["p"], events["t"] = x, y, p, t
    return events


def is_event_array(a: object) -> bool:
    return isinstance(a, np.ndarray) and a.dtype == EVENT_CD_DTYPE and a.ndim == 1
