"""Aggregates over typed recording results: means and medians that skip what is missing, groups
by condition in a natural order, the sweep subset of one axis, the engines and bandwidth rows."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

from darkread.lab.eval.results import Bandwidth, RecordingResult

_ORDER = {"still": 0, "normal": 1, "walking": 2, "letters": 0, "words": 1, "pangram": 2, "paragraph": 3}


def mean(values: Iterable[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return sum(kept) / len(kept) if kept else None


def median(values: Iterable[float | None]) -> float | None:
    kept = sorted(v for v in values if v is not None and not math.isnan(v))
    if not kept:
        return None
    mid = len(kept) // 2
    return kept[mid] if len(kept) % 2 else (kept[mid - 1] + kept[mid]) / 2


def sort_key(value: Any) -> Any:
    """Numbers ascending, then known categories in their natural order, then the rest by name."""
    if isinstance(value, tuple):
        return tuple(sort_key(v) for v in value)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (0, float(value), "")
    return (1, float(_ORDER.get(value, 99)), str(value))


def group_by(results: Sequence[RecordingResult], key: str | tuple[str, ...]) -> dict[Any, list[RecordingResult]]:
    """Results grouped by one condition, or by a tuple of conditions (keys are then tuples)."""
    groups: dict[Any, list[RecordingResult]] = {}
    for r in results:
        value = tuple(r.condition(k) for k in key) if isinstance(key, tuple) else r.condition(key)
        groups.setdefault(value, []).append(r)
    return dict(sorted(groups.items(), key=lambda kv: sort_key(kv[0])))


def sweep_subset(results: Sequence[RecordingResult], key: str, *, min_values: int = 3) -> tuple[list[RecordingResult], str]:
    """The recordings of one (lux, motion, text kind) condition that vary ``key`` the most, so a sweep
    is not confounded by the other axes; all recordings when no condition has ``min_values`` values."""
    best: tuple[Any, list[RecordingResult]] | None = None
    for condition, group in group_by(results, ("lux", "motion", "kind")).items():
        if len({r.condition(key) for r in group}) >= min_values and (best is None or len(group) > len(best[1])):
            best = (condition, group)
    if best is None:
        return list(results), f"all {len(results)} recordings"
    (lux, motion, kind), group = best
    return group, f"{lux:g} lux, {motion} motion, {kind}: {len(group)} recordings"


def backend_names(results: Sequence[RecordingResult]) -> list[str]:
    """The OCR engines compared on darkread's pages, in the order they first appear."""
    names: list[str] = []
    for r in results:
        names += [name for name in r.backends if name not in names]
    return names


def bandwidth_rows(results: Sequence[RecordingResult]) -> list[Bandwidth]:
    return [r.bandwidth for r in results if r.bandwidth is not None]


def held_out_fonts(results: Sequence[RecordingResult]) -> set[str]:
    return {str(r.font) for r in results if r.held_out_font}


def paired(primary: Sequence[RecordingResult], beside: Sequence[RecordingResult]) -> list[tuple[RecordingResult, RecordingResult]]:
    """The recordings both runs evaluated, as (primary, beside) pairs in the primary's order: modes are
    compared on the same recordings even when one run covers fewer of them."""
    by_name = {r.name: r for r in beside}
    return [(r, by_name[r.name]) for r in primary if r.name in by_name]
