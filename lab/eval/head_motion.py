"""The head's motion from the gyroscope and from the events, against the simulator's true pose.

For each synthetic recording with an IMU stream: the scene's shift over every 20-ms slice as the
gyroscope predicts it (``edge.imu_motion.ImuHeadMotion``), as the event tracker measures it
(``edge.scene_motion.SceneMotion``, all events) and as the simulator's pose says it was (the page
centre's motion, ``lab.eval.true_motion.TrueHeadMotion``). The error of a slice is the length of the
difference between the estimated and the true shift (px); per recording, the median over the slices
each estimate covers, and over the slices both cover. ``darkread eval head-motion RECORDINGS...``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from darkread.edge.imu_motion import ImuHeadMotion
from darkread.edge.io.recording import open_recording
from darkread.edge.scene_motion import SLICE_US, SceneMotion
from darkread.lab.eval.true_motion import TrueHeadMotion
from darkread.models.train.windows import read_events

PUSH_EVENTS = 1 << 16  # events pushed to the tracker at a time, as the edge's reader does


@dataclass(frozen=True)
class HeadMotionErrors:
    recording: str
    lux: float
    motion: str
    slices: int
    true_px_p50: float  # the page's true motion per slice (median length)
    imu_covered: float  # share of slices the gyroscope's motion is known for
    tracker_covered: float
    imu_px_p50: float  # median error per slice
    tracker_px_p50: float
    imu_px_p50_shared: float  # on the slices both know
    tracker_px_p50_shared: float
    imu_px_p90: float
    tracker_px_p90: float


def _offsets(at: Callable[[int], tuple[float, float] | None], times: np.ndarray) -> np.ndarray:
    out = np.full((times.shape[0], 2), np.nan)
    for i, t in enumerate(times.tolist()):  # (one lookup per 20-ms slice: a few hundred per recording)
        value = at(int(t))
        if value is not None:
            out[i] = value
    return out


def _median(values: np.ndarray) -> float:
    return float(np.median(values)) if values.size else float("nan")


def measure(recording: str | Path, slice_us: int = SLICE_US) -> HeadMotionErrors:
    """The gyroscope's and the tracker's errors per slice on one synthetic recording."""
    path = Path(recording)
    rec = open_recording(path)
    track = rec.imu()
    if track is None:
        raise ValueError(f"{path}: no IMU stream (closed_loop_trajectory.csv); make it with `darkread synth recording`")
    truth = TrueHeadMotion.from_recording(path)
    imu = ImuHeadMotion.of_track(track, rec.calibration)
    _, events, sensor_wh = read_events(path)
    tracker = SceneMotion(sensor_wh)
    for start in range(0, events.shape[0], PUSH_EVENTS):
        tracker.push(events[start : start + PUSH_EVENTS])
    t0, t1 = int(events["t"][0]), int(events["t"][-1])
    ends = np.arange(t0 + slice_us, t1 + 1, slice_us)
    times = np.concatenate([[ends[0] - slice_us], ends])
    true = np.diff(_offsets(truth.scene_px, times), axis=0)
    by_imu = np.diff(_offsets(imu.scene_px, times), axis=0)
    by_tracker = np.diff(_offsets(tracker.at, times), axis=0)
    ok = np.isfinite(true).all(axis=1)
    imu_error = np.linalg.norm(by_imu - true, axis=1)
    tracker_error = np.linalg.norm(by_tracker - true, axis=1)
    has_imu, has_tracker = ok & np.isfinite(imu_error), ok & np.isfinite(tracker_error)
    both = has_imu & has_tracker
    n = max(int(ok.sum()), 1)
    return HeadMotionErrors(
        recording=path.name, lux=float(rec.meta.get("lux", 0.0)), motion=str(rec.meta.get("motion", "")),
        slices=int(ok.sum()), true_px_p50=_median(np.linalg.norm(true[ok], axis=1)),
        imu_covered=float(has_imu.sum() / n), tracker_covered=float(has_tracker.sum() / n),
        imu_px_p50=_median(imu_error[has_imu]), tracker_px_p50=_median(tracker_error[has_tracker]),
        imu_px_p50_shared=_median(imu_error[both]), tracker_px_p50_shared=_median(tracker_error[both]),
        imu_px_p90=float(np.percentile(imu_error[has_imu], 90)) if has_imu.any() else float("nan"),
        tracker_px_p90=float(np.percentile(tracker_error[has_tracker], 90)) if has_tracker.any() else float("nan"),
    )


def table(rows: list[HeadMotionErrors]) -> str:
    """A Markdown table of the measured errors, one recording a row."""
    lines = ["| recording | lux | motion | slices | true motion per slice | gyroscope error (known) | "
             "tracker error (known) | on shared slices: gyroscope / tracker | p90: gyroscope / tracker |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r.recording} | {r.lux:g} | {r.motion} | {r.slices} | {r.true_px_p50:.2f} px | "
                     f"{r.imu_px_p50:.2f} px ({r.imu_covered:.0%}) | {r.tracker_px_p50:.2f} px ({r.tracker_covered:.0%}) | "
                     f"{r.imu_px_p50_shared:.2f} / {r.tracker_px_p50_shared:.2f} px | {r.imu_px_p90:.2f} / {r.tracker_px_p90:.2f} px |")
    return "\n".join(lines) + "\n"


def write_head_motion(recordings: list[str | Path], out: Path | None = None) -> str:
    """Measure every recording; the table (also written to ``out``, a .md, with a .json beside it)."""
    rows = [measure(r) for r in recordings]
    text = table(rows)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
        out.with_suffix(".json").write_text(json.dumps([asdict(r) for r in rows], indent=1) + "\n", encoding="utf-8")
    return text
