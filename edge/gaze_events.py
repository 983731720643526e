"""Online gaze events: fixations, saccades (return sweeps marked) and blinks from the tracker's rows.

Why not velocity thresholds (I-VT): at Aria's 10 Hz a 2 deg reading saccade shows as 20 deg/s, under
any usable threshold, and at 90 Hz per-row noise of 0.35 deg alone makes ~45 deg/s. Why not plain
dispersion (I-DT): a fixed dispersion of 1 deg is exceeded by the noise itself within a few rows,
and reading saccades of 0.5-1 deg (a third of them on real readers) stay under it.

What this does instead: a *step detector on position*. A fixation is a run of rows around one
place; its centre is the mean of its recent rows. Each new row waits in a look-ahead of
``lookahead_ms`` (the delay bound); when the median of the look-ahead lies further from the centre
than the noise allows (``z`` standard deviations of the difference of the two means, the noise
estimated online from the fixation rows themselves), the fixation has ended: the rows of the
look-ahead still near the old centre stay with it, rows near neither are the saccade in flight, the
rest start the next fixation. A small step is often seen a few rows late, when its first rows
already joined the run: on a change the split is refined over the run's last ``refine_rows`` rows
and the look-ahead (the best two-segment split), and the rows after it move to the new fixation.
Reading saccades run along the line, while the tracker's slow error wanders both ways: in the step
and merge tests a vertical difference counts ``across_weight`` (0.5) of a horizontal one (a return
sweep still shows by its 10-20 deg along the line; a page tilted by 20 deg loses 5 % of a
saccade). With a single row of look-ahead (10 Hz) both stay off. A fixation is accepted once it
lasted ``min_fixation_ms``; two accepted fixations that the test cannot tell apart with all their
rows are merged (a split by noise), so a fixation is reported when the next one is accepted, or
at a blink. A gap in valid
rows longer than ``blink_gap_ms`` (invalid rows, or rows the tracker dropped) is a blink. A
saccade that goes left by ``sweep_min_deg`` without rising more than ``sweep_max_rise_deg`` is a
return sweep.

Coordinates: degrees, x towards the end of a line (right), y down the page; convert Aria CPF
angles with ``angles_from_cpf``. Times: µs on any one clock. ``classify_gaze`` runs the same online
classifier over arrays.

Cost: the look-ahead holds a handful of rows, so the per-row work is plain float arithmetic on
them (numpy's per-call overhead on arrays that small was 20x the arithmetic: ~230 µs a row, a
quarter of the edge's budget at 20x real time); the noise estimate keeps its recent differences
sorted, so the lower quartile is read off instead of recomputed (a percentile of 480 values per
row was a third of the classifier's time). The arithmetic follows numpy's summation order
(:func:`_mean` is numpy's pairwise sum), so the results are the ones the numpy formulation gave.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, replace
from enum import IntEnum
from functools import cached_property

import numpy as np

Q25_ABS_NORMAL = 0.3186  # lower quartile of |N(0, 1)|
IN_FLIGHT_FRACTION = 0.5  # a row that made less of the step than this belongs to the saccade
NOISE_QUANTILE = 0.25
MIN_NOISE_DIFFS = 32  # fewer differences keep the first guess
PAIRWISE_BLOCK = 128  # numpy's pairwise-summation block (``PW_BLOCKSIZE``)

class EventKind(IntEnum):
    FIXATION = 1
    SACCADE = 2
    SWEEP = 3  # a return sweep: the saccade from a line's end to the start of another line
    BLINK = 4


EVENT_DTYPE = np.dtype([
    ("kind", "u1"),  # EventKind
    ("t0_us", "i8"),  # first row of a fixation; last row before a saccade or blink
    ("t1_us", "i8"),  # last row of a fixation; first row after a saccade or blink
    ("x", "f8"),  # fixation: mean position; saccade: where it landed (deg)
    ("y", "f8"),
    ("dx", "f8"),  # saccade: landing minus launch fixation centre (deg); 0 otherwise
    ("dy", "f8"),
    ("n_rows", "u4"),  # rows inside the fixation
])


@dataclass(frozen=True)
class GazeEventConfig:
    """Thresholds; ``for_rate`` sets the tracker's nominal rate, from which row counts follow."""

    rate_hz: float = 60.0
    lookahead_ms: float = 120.0  # rows held back before a change is decided: the detection delay
    z: float = 3.5  # step test, in standard deviations of a difference of means
    min_step_deg: float = 0.3  # never split on a smaller move, whatever the noise estimate
    noise_deg: float = 0.35  # first guess of the per-row noise (per axis), refined online
    min_noise_deg: float = 0.02
    noise_rows: int = 240  # recent row-to-row differences that make the noise estimate
    min_fixation_ms: float = 70.0  # shorter runs are part of a saccade
    blink_gap_ms: float = 75.0  # longer gaps between valid rows are blinks (at least 2.5 rows)
    centre_ms: float = 230.0  # recent rows that make a fixation's centre (it follows slow tracker drift)
    sweep_min_deg: float = 4.0
    sweep_max_rise_deg: float = 1.5
    across_weight: float = 0.5  # vertical differences count this much in the step and merge tests
    refine_rows: int = 6  # on a change, rows of the run's tail that the refined change point may take

    def for_rate(self, rate_hz: float) -> GazeEventConfig:
        return replace(self, rate_hz=float(rate_hz))

    @cached_property  # read per row: derived once (frozen, so it never goes stale)
    def period_us(self) -> float:
        return 1e6 / self.rate_hz

    @cached_property
    def centre_rows(self) -> int:
        return max(2, int(round(self.centre_ms * self.rate_hz / 1000.0)))

    @cached_property
    def lookahead_rows(self) -> int:
        return max(1, int(round(self.lookahead_ms * self.rate_hz / 1000.0)))

    @cached_property
    def reading_tests(self) -> bool:
        """Anisotropic tests and refined change points need a look-ahead of two rows or more: at
        10 Hz one row is all there is, and the single-row test stays isotropic."""
        return self.lookahead_rows >= 2

    @cached_property
    def y_weight(self) -> float:
        return self.across_weight if self.reading_tests else 1.0

    @cached_property
    def blink_gap_us(self) -> float:
        return max(self.blink_gap_ms * 1000.0, 2.5 * self.period_us)

    def __post_init__(self) -> None:
        if min(self.rate_hz, self.z, self.noise_deg, self.centre_ms, self.lookahead_ms) <= 0:
            raise ValueError("rate_hz, z, noise_deg, centre_ms and lookahead_ms must be positive")


@dataclass(frozen=True)
class GazeStatus:
    """What the eye is doing now, as far as the classifier can tell (for gating work on fixations).

    ``kind`` is FIXATION while rows sit around one place (``accepted`` once it lasted the minimum
    duration), SACCADE when the latest rows left it, BLINK when valid rows stopped; ``since_us`` is
    the first row of that state, (x, y) the fixation centre (NaN otherwise)."""

    kind: EventKind | None
    since_us: int
    x: float
    y: float
    accepted: bool


def angles_from_cpf(yaw_rad: np.ndarray, pitch_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Aria CPF angles (x left, y up) -> (x right, y down) in degrees, the classifier's frame."""
    return -np.degrees(np.asarray(yaw_rad, dtype=np.float64)), -np.degrees(np.asarray(pitch_rad, dtype=np.float64))


class _Run:
    """Rows of one fixation candidate (kept whole: a few hundred at most)."""

    __slots__ = ("t", "x", "y", "_centre")

    def __init__(self) -> None:
        self.t: list[int] = []
        self.x: list[float] = []
        self.y: list[float] = []
        self._centre: tuple[int, int | None, tuple[float, float]] | None = None  # (rows, last, centre)

    def add(self, t: int, x: float, y: float) -> None:
        self.t.append(t)
        self.x.append(x)
        self.y.append(y)

    def extend(self, other: _Run) -> None:
        self.t += other.t
        self.x += other.x
        self.y += other.y

    def __len__(self) -> int:
        return len(self.t)

    def centre(self, last: int | None = None) -> tuple[float, float]:
        """Mean of the ``last`` rows (all without it); rows are only ever appended, so the row
        count says whether the cached value is still the centre."""
        n = len(self.t)
        cached = self._centre
        if cached is not None and cached[0] == n and cached[1] == last:
            return cached[2]
        k = -last if last else 0
        centre = (_mean(self.x[k:]), _mean(self.y[k:]))
        self._centre = (n, last, centre)
        return centre

    def cut(self, keep: int) -> list[tuple[int, float, float]]:
        """Remove and return the rows from ``keep`` on (a refined change point moved them on)."""
        moved = list(zip(self.t[keep:], self.x[keep:], self.y[keep:]))
        del self.t[keep:], self.x[keep:], self.y[keep:]
        self._centre = None
        return moved

    def duration_us(self, period_us: float) -> float:
        return (self.t[-1] - self.t[0]) + period_us if self.t else 0.0


class GazeEventClassifier:
    """Stateful online classifier: ``push`` rows as they arrive, get the events decided so far.

    A row is (t_us, x_deg, y_deg); NaN x or y marks an invalid row (blink, lost eye). Events come
    out in time order, each once; a fixation is reported when the next one is accepted (at most
    ``lookahead_ms + min_fixation_ms`` after the saccade) or when a blink or ``flush`` ends it.
    Not thread-safe: one owner pushes and reads.
    """

    def __init__(self, cfg: GazeEventConfig = GazeEventConfig()) -> None:
        self.cfg = cfg
        self._buf: deque[tuple[int, float, float]] = deque()
        self._run = _Run()  # the current fixation candidate
        self._accepted = False
        self._prev: _Run | None = None  # last accepted fixation, reported when the next one is
        self._last_valid_us: int | None = None
        self._now_us: int | None = None
        self._sigma2 = cfg.noise_deg**2
        self._last_xy: tuple[float, float] | None = None
        self._diffs: deque[float] = deque(maxlen=2 * cfg.noise_rows)  # arrival order
        self._sorted_diffs: list[float] = []  # the same values, sorted

    @property
    def noise_deg(self) -> float:
        """Current estimate of the per-row tracker noise (deg, per axis)."""
        return math.sqrt(self._sigma2)

    # -- public API -------------------------------------------------------------------------------
    def push(self, t_us, x_deg, y_deg) -> np.ndarray:
        """Feed one row or arrays of rows (time order); returns the events decided (EVENT_DTYPE)."""
        t = np.atleast_1d(np.asarray(t_us, dtype=np.int64))
        x = np.atleast_1d(np.asarray(x_deg, dtype=np.float64))
        y = np.atleast_1d(np.asarray(y_deg, dtype=np.float64))
        if not (t.shape == x.shape == y.shape) or t.ndim != 1:
            raise ValueError("t_us, x_deg and y_deg must have one value per row")
        return self.push_rows(zip(t.tolist(), x.tolist(), y.tolist()))

    def push_rows(self, rows: Iterable[tuple[int, float, float]]) -> np.ndarray:
        """``push`` for rows already in Python, (t_us, x_deg, y_deg) each: a live gate pushes one or
        two rows at a time, for which building arrays costs more than classifying them."""
        out: list[tuple] = []
        push_row = self._push_row
        for ti, xi, yi in rows:
            push_row(ti, xi, yi, out)
        return _events(out)

    def flush(self) -> np.ndarray:
        """End of the stream: decide the rows held back and report the open fixation."""
        out: list[tuple] = []
        self._drain(out)
        self._end_run(out)
        self._report_prev(out)
        return _events(out)

    def status(self) -> GazeStatus:
        cfg = self.cfg
        now = self._now_us if self._now_us is not None else 0
        if self._last_valid_us is None or now - self._last_valid_us > cfg.blink_gap_us:
            since = self._last_valid_us if self._last_valid_us is not None else now
            return GazeStatus(EventKind.BLINK if self._last_valid_us is not None else None, int(since), math.nan, math.nan, False)
        if len(self._run):
            cx, cy = self._run.centre(cfg.centre_rows)
            if self._buf and self._is_away(self._buf[-1][1:], (cx, cy), 1):
                return GazeStatus(EventKind.SACCADE, int(self._buf[-1][0]), math.nan, math.nan, False)
            return GazeStatus(EventKind.FIXATION, int(self._run.t[0]), cx, cy, self._accepted)
        since = self._buf[0][0] if self._buf else now
        return GazeStatus(EventKind.SACCADE, int(since), math.nan, math.nan, False)

    # -- the decision -----------------------------------------------------------------------------
    def _push_row(self, t: int, x: float, y: float, out: list[tuple]) -> None:
        self._now_us = t
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        last = self._last_valid_us
        if last is not None and t - last > self.cfg.blink_gap_us:
            self._drain(out)
            self._end_run(out)
            self._report_prev(out)
            out.append((EventKind.BLINK, last, t, math.nan, math.nan, 0.0, 0.0, 0))
        if last is not None and self._last_xy is not None:
            self._update_noise(t - last, x - self._last_xy[0], y - self._last_xy[1])
        self._last_valid_us = t
        self._last_xy = (x, y)
        self._buf.append((t, x, y))
        if len(self._buf) >= self.cfg.lookahead_rows:
            self._decide(out)

    def _drain(self, out: list[tuple]) -> None:
        while self._buf:
            self._decide(out)

    def _threshold(self, n_a: int, n_b: int) -> float:
        cfg = self.cfg
        return max(cfg.min_step_deg, cfg.z * math.sqrt(self._sigma2 * (1.0 / n_a + 1.0 / n_b)))

    def _is_away(self, xy, centre, n_ahead: int) -> bool:
        n_run = min(len(self._run), self.cfg.centre_rows) or 1
        return math.hypot(xy[0] - centre[0], xy[1] - centre[1]) > self._threshold(n_ahead, n_run)

    def _decide(self, out: list[tuple]) -> None:
        """Decide the oldest row of the look-ahead (or, on a change, the whole look-ahead)."""
        cfg = self.cfg
        buf = self._buf
        single = self._threshold(1, 1 << 30)
        if not len(self._run):  # no fixation: start one at the oldest row unless it is in flight
            n_ahead = len(buf)
            mx, my = _median([row[1] for row in buf]), _median([row[2] for row in buf])
            t, x, y = buf.popleft()
            if math.hypot(x - mx, y - my) <= single or n_ahead == 1:
                self._run.add(t, x, y)
                self._check_accept(out)
            return
        c = self._run.centre(cfg.centre_rows)
        split = self._change_point(buf, c)
        if split is not None:
            rows = list(buf)
            buf.clear()
            keep = self._refined_split(rows, split) if self._accepted and cfg.reading_tests else None
            if keep is not None:  # the change came before the look-ahead: the run's last rows move on
                moved = self._run.cut(keep)
                candidate, launch = moved + rows, self._run.centre(cfg.centre_rows)
            elif self._accepted or self._prev is None:
                for row in rows[:split]:  # before the change: the old fixation, or the saccade in flight
                    if math.dist(row[1:], c) <= single:
                        self._run.add(*row)
                candidate, launch = rows[split:], c
            else:  # a young run (too short to be a fixation) may have been the start of the new one
                young = list(zip(self._run.t, self._run.x, self._run.y))
                candidate, launch = young + rows, self._prev.centre(cfg.centre_rows)
                self._run = _Run()
            self._end_run(out)
            for row in candidate[self._in_flight(candidate, launch):]:
                self._run.add(*row)
            self._check_accept(out)
            return
        t, x, y = buf.popleft()
        if math.hypot(x - c[0], y - c[1]) > single:
            return  # a wild row: neither fixation nor (yet) a change
        self._run.add(t, x, y)
        self._check_accept(out)

    def _refined_split(self, rows: list[tuple[int, float, float]], split: int) -> int | None:
        """Rows of the run to keep when the change happened before the look-ahead, else None.

        A small step is often found a few rows late: its first rows already went into the run. The
        best two-segment split over the run's last ``refine_rows`` rows and the look-ahead (centre
        rows before, every row after, the statistic |mean difference|^2 * n_a n_b / (n_a + n_b))
        places it; the run keeps at least ``min_fixation_ms``."""
        cfg = self.cfg
        run = self._run
        n = len(run)
        lo = max(1, n - cfg.refine_rows)
        t_min = run.t[0] + cfg.min_fixation_ms * 1000.0 - cfg.period_us  # the run must last that long
        base = lo - min(lo, cfg.centre_rows)  # index of xs[0] in the run
        xs, ys = run.x[base:], run.y[base:]
        xs = xs + [r[1] for r in rows]
        ys = ys + [r[2] for r in rows]
        px, py = [0.0], [0.0]
        for a, b in zip(xs, ys):  # prefix sums
            px.append(px[-1] + a)
            py.append(py[-1] + b)
        total, w, nc = len(xs), cfg.y_weight, cfg.centre_rows
        best, best_j = -1.0, None
        for j in range(lo, n + split + 1):  # j: first row after the change (index in run + rows)
            if j <= n and run.t[j - 1] < t_min:
                continue
            jj = j - base
            a0 = max(0, jj - nc)
            n_a, n_b = jj - a0, total - jj
            dx = (px[jj] - px[a0]) / n_a - (px[total] - px[jj]) / n_b
            dy = w * ((py[jj] - py[a0]) / n_a - (py[total] - py[jj]) / n_b)
            stat = (dx * dx + dy * dy) * n_a * n_b / (n_a + n_b)
            if stat > best:
                best, best_j = stat, j
        return best_j if best_j is not None and best_j < n else None

    def _in_flight(self, rows: list[tuple[int, float, float]], old: tuple[float, float]) -> int:
        """Leading rows of a new fixation that are still on the way: short of ``IN_FLIGHT_FRACTION``
        of the step to the mean of the rows after them, or off that mean by more than the noise."""
        single = self._threshold(1, 1 << 30)
        ox, oy = old
        n = len(rows)
        k = 0
        while k < n - 1:
            sx = sy = 0.0
            for row in rows[k + 1:]:  # in order: the sums numpy's mean over axis 0 makes
                sx += row[1]
                sy += row[2]
            rx, ry = sx / (n - k - 1), sy / (n - k - 1)
            step_x, step_y = rx - ox, ry - oy
            x, y = rows[k][1], rows[k][2]
            along = ((x - ox) * step_x + (y - oy) * step_y) / max(step_x * step_x + step_y * step_y, 1e-12)
            if along >= IN_FLIGHT_FRACTION and math.hypot(x - rx, y - ry) <= single:
                break
            k += 1
        return k

    def _change_point(self, rows: deque[tuple[int, float, float]], centre: tuple[float, float]) -> int | None:
        """Index of the look-ahead row where a new fixation starts, or None: the suffix whose mean
        lies furthest from the centre in units of its threshold, if that exceeds 1."""
        cfg = self.cfg
        inv_run = 1.0 / min(len(self._run), cfg.centre_rows)
        k = len(rows)
        cx, cy = centre
        sigma2, z, min_step, w = self._sigma2, cfg.z, cfg.min_step_deg, cfg.y_weight
        last_is_single = k >= cfg.lookahead_rows and k > 1  # a single newest row is not yet a fixation elsewhere
        best, best_ratio = k - 1, -1.0
        sx = sy = 0.0
        for i in range(k - 1, -1, -1):  # suffix sums from the newest row, as a cumulative sum makes them
            _, x, y = rows[i]
            sx += x
            sy += y
            count = k - i
            ratio = math.hypot(sx / count - cx, w * (sy / count - cy)) / max(
                min_step, z * math.sqrt(sigma2 * (1.0 / count + inv_run)))
            if i == k - 1 and last_is_single:
                ratio = 0.0
            if ratio >= best_ratio:  # ties go to the earlier row, as argmax does
                best, best_ratio = i, ratio
        return best if best_ratio > 1.0 else None

    def _update_noise(self, dt_us: float, dx: float, dy: float) -> None:
        """Per-row noise from successive differences of valid rows (robust: lower quartile of |d|,
        so the saccades among them do not count)."""
        if dt_us > 2.5 * self.cfg.period_us:
            return
        self._add_diff(abs(dx))
        self._add_diff(abs(dy))
        if len(self._sorted_diffs) >= MIN_NOISE_DIFFS:
            q = _sorted_quantile(self._sorted_diffs, NOISE_QUANTILE)
            sigma = q / (Q25_ABS_NORMAL * math.sqrt(2.0))
            self._sigma2 = max(sigma, self.cfg.min_noise_deg) ** 2

    def _add_diff(self, d: float) -> None:
        """The newest difference in; beyond ``2 * noise_rows`` the oldest out (the window stays sorted)."""
        diffs, ordered = self._diffs, self._sorted_diffs
        if len(diffs) == diffs.maxlen:
            del ordered[bisect.bisect_left(ordered, diffs[0])]
        diffs.append(d)
        bisect.insort(ordered, d)

    def _check_accept(self, out: list[tuple]) -> None:
        cfg = self.cfg
        if self._accepted or self._run.duration_us(cfg.period_us) < cfg.min_fixation_ms * 1000.0:
            return
        self._accepted = True
        prev = self._prev
        if prev is None:
            return
        n_p, n_r = min(len(prev), cfg.centre_rows), min(len(self._run), cfg.centre_rows)
        cp = prev.centre(cfg.centre_rows)
        cr = self._run.centre(cfg.centre_rows)
        close_in_time = self._run.t[0] - prev.t[-1] <= cfg.blink_gap_us
        if close_in_time and math.hypot(cp[0] - cr[0], cfg.y_weight * (cp[1] - cr[1])) <= self._threshold(n_p, n_r):
            prev.extend(self._run)  # the two cannot be told apart: one fixation split by noise
            self._run = prev
            self._prev = None
            return
        self._report_prev(out)
        dx, dy = cr[0] - cp[0], cr[1] - cp[1]
        sweep = dx <= -cfg.sweep_min_deg and dy >= -cfg.sweep_max_rise_deg
        kind = EventKind.SWEEP if sweep else EventKind.SACCADE
        out.append((kind, prev.t[-1], self._run.t[0], cr[0], cr[1], dx, dy, 0))

    def _end_run(self, out: list[tuple]) -> None:
        """The candidate ended: keep it (to report or merge) if accepted, else it was saccade."""
        if self._accepted and len(self._run):
            if self._prev is not None:  # (only after a merge race; report the older one)
                self._report_prev(out)
            self._prev = self._run
        self._run = _Run()
        self._accepted = False

    def _report_prev(self, out: list[tuple]) -> None:
        prev = self._prev
        if prev is None:
            return
        cx, cy = prev.centre()
        out.append((EventKind.FIXATION, prev.t[0], prev.t[-1], cx, cy, 0.0, 0.0, len(prev)))
        self._prev = None


def _events(rows: list[tuple]) -> np.ndarray:
    if not rows:
        return np.zeros(0, dtype=EVENT_DTYPE)
    return np.array(rows, dtype=EVENT_DTYPE)


def _pairwise_sum(values: list[float], lo: int, n: int) -> float:
    """numpy's pairwise summation of ``values[lo:lo + n]`` (``pairwise_sum_DOUBLE``), same order."""
    if n < 8:
        total = -0.0
        for i in range(lo, lo + n):
            total += values[i]
        return total
    if n <= PAIRWISE_BLOCK:
        r = values[lo : lo + 8]
        i = 8
        whole = n - n % 8
        while i < whole:
            r = [r[j] + values[lo + i + j] for j in range(8)]
            i += 8
        total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for j in range(lo + i, lo + n):
            total += values[j]
        return total
    half = n // 2
    half -= half % 8
    return _pairwise_sum(values, lo, half) + _pairwise_sum(values, lo + half, n - half)


def _mean(values: list[float]) -> float:
    """``np.mean(values)`` of a short list, bit for bit, without building an array."""
    return _pairwise_sum(values, 0, len(values)) / len(values)


def _median(values: list[float]) -> float:
    """``np.median`` of a short list (the mean of the two middle values when their count is even)."""
    ordered = sorted(values)
    n = len(ordered)
    mid = n // 2
    return ordered[mid] if n % 2 else (ordered[mid - 1] + ordered[mid]) / 2.0


def _sorted_quantile(ordered: list[float], q: float) -> float:
    """``np.percentile(values, 100 * q)`` (linear method) of already sorted values, same arithmetic."""
    n = len(ordered)
    index = n * q + (1.0 - q) - 1.0  # numpy's virtual index for the linear method
    below = math.floor(index)
    gamma = index - below
    lo = min(max(int(below), 0), n - 1)
    a, b = ordered[lo], ordered[min(lo + 1, n - 1)]
    diff = b - a
    return b - diff * (1.0 - gamma) if gamma >= 0.5 else a + diff * gamma


def classify_gaze(t_us: np.ndarray, x_deg: np.ndarray, y_deg: np.ndarray, cfg: GazeEventConfig = GazeEventConfig()) -> np.ndarray:
    """All events of a recorded stream: the online classifier run over it (same result as live)."""
    clf = GazeEventClassifier(cfg)
    return np.concatenate([clf.push(t_us, x_deg, y_deg), clf.flush()])


def fixations(events: np.ndarray) -> np.ndarray:
    return events[events["kind"] == EventKind.FIXATION]
