from __future__ import annotations

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE, empty_events, is_event_array, make_events


def test_dtype_is_byte_identical_to_openeb_eventcd() -> None:
    assert EVENT_CD_DTYPE.itemsize == 16
    assert [EVENT_CD_DTYPE.fields[n][1] for n in ("x", "y", "p", "t")] == [0, 2, 4, 8]
    assert TRIGGER_DTYPE.itemsize == 24 and TRIGGER_DTYPE.fields["id"][1] == 16


def test_empty_window_is_a_zero_length_array_not_none() -> None:
    ev = empty_events()
    assert is_event_array(ev) and len(ev) == 0


def test_make_events_broadcasts_columns() -> None:
    ev = make_events([1, 2, 3], 5, 1, np.array([10, 20, 30]))
    assert ev["y"].tolist() == [5, 5, 5] and ev["t"].tolist() == [10, 20, 30]
