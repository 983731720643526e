"""Batch jobs in turn or in worker processes: the same results in the items' order."""

from __future__ import annotations

import pytest

from darkread.lab.jobs import run_jobs


def _square_slowly_for_small(n: int) -> int:
    """Squares; small numbers take longer, so worker processes finish out of order."""
    import time

    time.sleep(0.02 * (5 - n) if n < 5 else 0.0)
    return n * n


def _fail_on_three(n: int) -> int:
    if n == 3:
        raise ValueError("three is not allowed")
    return n


@pytest.mark.parametrize("jobs", [1, 2])
def test_results_come_in_the_items_order_and_each_is_counted(jobs: int) -> None:
    ticks: list[int] = []
    assert run_jobs(_square_slowly_for_small, range(8), jobs, lambda: ticks.append(1)) == [n * n for n in range(8)]
    assert len(ticks) == 8
    assert run_jobs(_square_slowly_for_small, [], jobs) == []


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_failed_task_stops_the_run_with_its_error(jobs: int) -> None:
    with pytest.raises(ValueError, match="three is not allowed"):
        run_jobs(_fail_on_three, range(6), jobs)
