"""The compiled counting loops count exactly what the numpy formulation counts (it is their oracle here)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from darkread.edge.binning import add_cell_counts, cell_tables, slice_counts, voters, warm_up
from darkread.edge.events import make_events


def random_events(seed: int, n: int, width: int = 1300, height: int = 740, span_us: int = 40_000):
    """Events over (a little more than) a 1280x720 sensor, time-sorted, with repeated times."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, span_us, n))
    return make_events(rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n), t)


def cells_numpy(events, grid_wh: tuple[int, int], cell_px: int) -> np.ndarray:
    cols, rows = grid_wh
    cx = np.minimum(events["x"].astype(np.intp) // cell_px, cols - 1)
    cy = np.minimum(events["y"].astype(np.intp) // cell_px, rows - 1)
    return cy * cols + cx


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), st.integers(0, 3000), st.sampled_from([1, 4, 8, 16]), st.data())
def test_cell_counts_are_a_bincount_of_each_events_clipped_cell(seed: int, n: int, cell_px: int, data: st.DataObject) -> None:
    events = random_events(seed, n)
    grid = (-(-1280 // cell_px), -(-720 // cell_px))
    start = data.draw(st.integers(0, n))
    stop = data.draw(st.integers(start, n))
    out = np.full(grid[0] * grid[1], 7, np.int64)  # counts are added to what is there
    columns, rows = cell_tables(grid[0] * cell_px, grid[1] * cell_px, cell_px)
    add_cell_counts(events["x"], events["y"], start, stop, columns, rows, out)
    expected = 7 + np.bincount(cells_numpy(events[start:stop], grid, cell_px), minlength=out.shape[0])
    np.testing.assert_array_equal(out, expected)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**31), st.integers(0, 4000), st.integers(0, 1200), st.integers(0, 700),
    st.integers(1, 400), st.integers(1, 300), st.integers(0, 30_000), st.integers(1, 30_000),
    st.integers(2, 4), st.integers(1, 3), st.integers(1, 5),
)
def test_slice_counts_match_the_numpy_selection_and_bincounts(
    seed: int, n: int, x0: int, y0: int, width: int, height: int, t_first: int, length: int, slices: int, cell: int, pad: int,
) -> None:
    events = random_events(seed, n)
    t_last = t_ref = t_first + length
    x, y, t = events["x"], events["y"], events["t"]
    inside = ((x - np.uint16(x0)) < width) & ((y - np.uint16(y0)) < height) & (t >= t_first) & (t <= t_last)
    count, earliest = voters(x, y, t, x0, y0, width, height, t_first, t_last)
    assert count == np.count_nonzero(inside)
    assert earliest == (int(t[inside].min()) if count else t_last)
    if not count:
        return
    span = float(length)
    age = (t_ref - t[inside].astype(np.float64)) / span
    oldest = float(age.max())
    if not oldest > 0:
        return
    shape = (-(-height // cell) + 2 * pad, -(-width // cell) + 2 * pad)
    slot = np.clip((age * (slices / oldest)).astype(np.intp), 0, slices - 1)
    cy = (y[inside].astype(np.intp) - y0) // cell + pad
    cx = (x[inside].astype(np.intp) - x0) // cell + pad
    expected = np.bincount((slot * shape[0] + cy) * shape[1] + cx, minlength=slices * shape[0] * shape[1]).reshape(slices, *shape)
    images = np.zeros((slices, shape[0] * shape[1]), np.float32)
    counts, age_sums = np.zeros(slices, np.int64), np.zeros(slices, np.float64)
    columns, rows = cell_tables(width, height, cell, pad, row_stride=shape[1])
    slice_counts(x, y, t, x0, y0, columns, rows, t_first, t_last, t_ref, span, oldest, images, counts, age_sums)
    np.testing.assert_array_equal(images.reshape(slices, *shape), expected.astype(np.float32))
    np.testing.assert_array_equal(counts, np.bincount(slot, minlength=slices))
    np.testing.assert_array_equal(age_sums, np.bincount(slot, weights=age, minlength=slices))  # same order, same sums


def test_warm_up_compiles_the_signatures_the_edge_uses() -> None:
    warm_up()
    events = random_events(1, 500)
    before = (len(add_cell_counts.signatures), len(voters.signatures), len(slice_counts.signatures))
    add_cell_counts(events["x"], events["y"], 0, 500, *cell_tables(1280, 720, 8), np.zeros(160 * 90, np.float32))
    voters(events["x"], events["y"], events["t"], 0, 0, 100, 100, 0, 10_000)
    columns, rows = cell_tables(100, 100, 2, 3, row_stride=60)
    slice_counts(events["x"], events["y"], events["t"], 0, 0, columns, rows, 0, 10_000, 10_000, 10_000.0, 1.0,
                 np.zeros((3, 60 * 60), np.float32), np.zeros(3, np.int64), np.zeros(3, np.float64))
    assert (len(add_cell_counts.signatures), len(voters.signatures), len(slice_counts.signatures)) == before  # nothing new compiled
