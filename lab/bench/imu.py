"""The gyroscope's live path: what a datagram costs once the edge holds a long history.

A live IMU feed (``edge.sources.imu_feed``) hands ``ImuHeadMotion.extend`` a datagram of 20 samples
every 20 ms (1 kHz). ``edge_imu_live_ms_per_s``: CPU per second of samples fed that way, over the
last ``MEASURED_S`` of a ``TRACK_S`` track: the most history a live stream holds (``keep_us`` and
its slack, just short of the trim). Reference, same run: the same track read at once, as a replay
does, per second of samples.
"""

from __future__ import annotations

import time

import numpy as np

from darkread.edge.imu_motion import KEEP_SLACK, ImuHeadMotion, ImuMotionConfig
from darkread.edge.io.calibration import Calibration
from darkread.lab.bench import BenchContext, Figure

DATAGRAM = 20  # samples per datagram (edge.sources.imu_feed: 20 ms at 1 kHz)
TRACK_S = KEEP_SLACK * ImuMotionConfig().keep_us / 1e6 - 0.1  # a live stream trims its history past this: just before
MEASURED_S = 10.0


def _track(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """1-kHz samples of a head drifting slowly, with a MEMS-like noise and bias."""
    rng = np.random.default_rng(46)
    n = int(seconds * 1000)
    t = 1_000_000_000 + np.arange(n, dtype=np.int64) * 1000
    drift = 0.03 * np.sin(2 * np.pi * 0.2 * np.arange(n) / 1000)[:, None]
    return t, rng.normal(0.0, 0.01, (n, 3)) + 0.004 + drift


def _calibration() -> Calibration:
    return Calibration(width=1280, height=720, fx=1400.0, fy=1400.0, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
                       T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=0)


def run(ctx: BenchContext) -> list[Figure]:
    seconds = TRACK_S if not ctx.smoke else 12.0
    t, omega = _track(seconds)
    live = ImuHeadMotion(_calibration(), live=True)
    measured_from = t.shape[0] - int(MEASURED_S * 1000) if not ctx.smoke else 0
    cpu = 0.0
    for k in range(0, t.shape[0], DATAGRAM):
        started = time.process_time()
        live.extend(t[k:k + DATAGRAM], omega[k:k + DATAGRAM])
        if k >= measured_from:
            cpu += time.process_time() - started
    measured_s = (t.shape[0] - measured_from) / 1000
    started = time.process_time()
    at_once = ImuHeadMotion(_calibration())
    at_once.extend(t, omega)
    once_ms = (time.process_time() - started) * 1e3 / seconds
    return [Figure(
        key="edge_imu_live_ms_per_s", value=round(cpu * 1e3 / measured_s, 2),
        label=f"gyroscope live, {DATAGRAM}-sample datagrams at 1 kHz, CPU ms per s of samples ({seconds:g}-s track, its last {measured_s:g} s)",
        reference=f"the same track read at once (a replay): {once_ms:.2f} ms per s", goal="informational",
    )]
