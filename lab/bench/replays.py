"""Many glasses at once, paced at real time, spread over several cloud instances on one database.

Each replay is the edge's own ``Uplink`` (spool, acks, failover) fed pre-encoded frames at
``FRAME_RATE_HZ``; replay i lists the instances rotated by i, so they start spread evenly and
each fails over to the next instance when its own is killed. Afterwards the database is asked
what it holds: every session must have seqs 0..n-1, each once, for the n frames it submitted.
Used by ``make bench`` (60 s) and, shorter, by the tests.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from darkread.edge.config import UplinkConfig
from darkread.edge.spool import Spool
from darkread.edge.uplink import Uplink
from darkread.proto.messages import Frame, pack_mask

FRAME_RATE_HZ = 30.0  # what one pair of glasses sends at most


@dataclass(frozen=True)
class ReplayOutcome:
    sessions: int
    seconds: float
    submitted: int  # frames the replays made
    stored: int  # rows the database holds for them
    lost: int  # submitted but not stored
    duplicated: int  # stored more than once (the primary key makes this 0; counted, not assumed)
    wrong_sessions: int  # sessions whose stored seqs are not exactly 0..n-1
    failovers: int
    drained: bool  # every uplink's spool emptied at the end

    @property
    def exactly_once(self) -> bool:
        return self.lost == 0 and self.duplicated == 0 and self.wrong_sessions == 0 and self.drained


def _frames() -> list[Frame]:
    rng = np.random.default_rng(1)
    frames = []
    for i in range(8):
        shape, bits = pack_mask(rng.random((100, 200)) < 0.08)
        frames.append(Frame(0, i, 0, (540, 310), (640.0, 360.0), (0.0, 0.0), 1600, shape, bits))
    return frames


def run_replays(
    urls: list[str],
    api_key: str,
    count_stored: Callable[[str], dict[str, tuple[int, int, int, int]]],
    *,
    sessions: int,
    seconds: float,
    at_half: Callable[[], None] | None = None,
    prefix: str = "replay",
) -> ReplayOutcome:
    """Run ``sessions`` paced replays for ``seconds``; ``at_half`` runs halfway (e.g. kill an instance).

    ``count_stored(prefix)`` answers, per session id starting with the prefix, (rows, distinct
    seqs, min seq, max seq) from the database.
    """
    frames = _frames()
    uplinks = []
    for i in range(sessions):
        order = urls[i % len(urls) :] + urls[: i % len(urls)]
        settings = UplinkConfig(
            url=",".join(order), api_key=api_key, device_id=f"{prefix}-{i}", session_id=f"{prefix}-{i}",
            backoff_initial_s=0.05, backoff_max_s=0.5, max_in_flight=256,
        )  # fmt: skip
        uplinks.append(Uplink(settings, Spool(None), sensor_wh=(1280, 720), fovea_hw=(100, 200)))
    for uplink in uplinks:
        uplink.start()
    submitted = [0] * sessions
    started = time.monotonic()
    ticks = int(seconds * FRAME_RATE_HZ)
    halfway = ticks // 2
    for tick in range(ticks):
        delay = started + tick / FRAME_RATE_HZ - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        if tick == halfway and at_half is not None:
            at_half()
        for i, uplink in enumerate(uplinks):
            uplink.submit(frames[(tick + i) % len(frames)])  # the uplink numbers it
            submitted[i] += 1
    elapsed = time.monotonic() - started
    drained = all([uplink.stop(drain_timeout_s=60) for uplink in uplinks])
    stored = count_stored(prefix)
    lost = duplicated = wrong = rows_total = 0
    for i in range(sessions):
        rows, distinct, low, high = stored.get(f"{prefix}-{i}", (0, 0, -1, -1))
        rows_total += rows
        lost += submitted[i] - distinct
        duplicated += rows - distinct
        wrong += not (rows == distinct == submitted[i] and low == 0 and high == submitted[i] - 1)
    return ReplayOutcome(
        sessions=sessions, seconds=elapsed, submitted=sum(submitted), stored=rows_total, lost=lost,
        duplicated=duplicated, wrong_sessions=wrong, drained=drained,
        failovers=sum(uplink.metrics.totals["failovers"] for uplink in uplinks),
    )  # fmt: skip


def count_stored_in(database_url: str) -> Callable[[str], dict[str, tuple[int, int, int, int]]]:
    """``count_stored`` for ``run_replays`` against the PostgreSQL database at ``database_url``."""
    import psycopg

    def count(prefix: str) -> dict[str, tuple[int, int, int, int]]:
        with psycopg.connect(database_url) as conn:
            rows = conn.execute(
                "SELECT session_id, count(*), count(DISTINCT seq), min(seq), max(seq) FROM frames"
                " WHERE starts_with(session_id, %s) GROUP BY session_id",
                (prefix + "-",),
            ).fetchall()
        return {session_id: (int(n), int(d), int(lo), int(hi)) for session_id, n, d, lo, hi in rows}

    return count
