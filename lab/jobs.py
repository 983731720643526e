"""Long batch jobs (suite recordings, evaluations, comparisons, rehearsal sessions) run in turn or
in worker processes, one shape for all of them."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import TypeVar

Item = TypeVar("Item")
Result = TypeVar("Result")


def run_jobs(task: Callable[[Item], Result], items: Iterable[Item], jobs: int = 1,
             done: Callable[[], object] | None = None) -> list[Result]:
    """``task(item)`` for every item: here in turn (``jobs`` <= 1), else in ``jobs`` worker processes
    (``task`` and the items must pickle: a module-level function or a ``functools.partial`` of one).
    Results come in the items' order; ``done`` is called after each (a progress bar's ``update``).
    A failed task stops the run with its error."""
    items = list(items)
    results: dict[int, Result] = {}
    if jobs <= 1:
        for k, item in enumerate(items):
            results[k] = task(item)
            if done is not None:
                done()
    else:

        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(task, item): k for k, item in enumerate(items)}
            for future in as_completed(futures):
                results[futures[future]] = future.result()
                if done is not None:
                    done()
    return [results[k] for k in range(len(items))]
