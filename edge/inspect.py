"""``darkread inspect PATH``: what is in a recording (directory) or a RAW file.

Streams the RAW file in chunks, so files larger than memory work, and reports the sensor, format,
duration, event count and rate, ON/OFF split, triggers and, for recordings, the gaze track and the
share of events that fall inside the 100 x 200 gaze window (the foveated fraction), and the IMU
stream when the recording has one (rate, duration, angular speed). ``--png`` draws the accumulated
events with the window track on top, and the scene's motion the gyroscope predicts.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

logger = logging.getLogger(__name__)

DEFAULT_CHUNK_BYTES = 4 << 20
PROGRESS_MIN_BYTES = 32 << 20  # smaller files decode in well under a second


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "inspect",
        help="summarise a recording directory or a .raw file",
        description=(
            "Summarise a recording (a directory in the recording format) or a Prophesee .raw file: "
            "sensor and format, duration, event count and rate, ON/OFF, triggers; for recordings also "
            "the gaze samples and the share of events inside the 100x200 gaze window."
        ),
    )
    parser.add_argument("path", help="recording directory or .raw file")
    parser.add_argument("--gaze-csv", "--gaze", dest="gaze", metavar="CSV",
                        help="eye-gaze CSV (for a bare .raw file, or to override the recording's)")
    parser.add_argument("--calibration", help="calibration.json (for a bare .raw file, or to override)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("--png", metavar="OUT", help="write an accumulated-event picture with the fovea track")
    parser.add_argument(
        "--chunk-mb", type=float, default=DEFAULT_CHUNK_BYTES / (1 << 20), help="decode chunk size in MiB (default 4)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    report = inspect_path(
        args.path,
        gaze=args.gaze,
        calibration=args.calibration,
        png=args.png,
        chunk_bytes=max(1 << 16, int(args.chunk_mb * (1 << 20))),
        progress=not args.no_progress,
    )
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(format_report(report))
    if report["problems"]:  # decoded, but not what the header says: the figures above are nonsense
        print(f"darkread: error: {report['path']} does not look like a valid recording: "
              f"{'; '.join(report['problems'])}", file=sys.stderr)
    return 1 if report["problems"] else 0


@dataclass
class EventSummary:
    """Running totals over event chunks (sums as Python ints: no overflow)."""

    events: int = 0
    on: int = 0
    t_first_us: int | None = None
    t_last_us: int | None = None
    sum_t_us: int = 0
    sum_x: int = 0
    sum_y: int = 0
    triggers: int = 0
    gaze_events: int = 0  # events with a usable gaze (a window exists)
    fovea_events: int = 0  # events inside their window
    counts: np.ndarray | None = field(default=None, repr=False)  # (H, W) accumulated events for --png

    def add(self, events: np.ndarray) -> None:
        n = int(events.shape[0])
        if n == 0:
            return
        t = events["t"]
        if self.t_first_us is None:
            self.t_first_us = int(t[0])
        self.t_last_us = int(t[-1])
        self.events += n
        self.on += int(np.count_nonzero(events["p"]))
        self.sum_t_us += int(t.sum(dtype=np.int64))
        self.sum_x += int(events["x"].sum(dtype=np.int64))
        self.sum_y += int(events["y"].sum(dtype=np.int64))

    @property
    def fovea_fraction(self) -> float:
        """Share of the events inside the gaze window (0 without events)."""
        return self.fovea_events / self.events if self.events else 0.0

    def accumulate_image(self, events: np.ndarray, width: int, height: int) -> None:
        if self.counts is None:
            self.counts = np.zeros(height * width, dtype=np.int64)
        inside = (events["x"] < width) & (events["y"] < height)
        pixel = events["y"][inside].astype(np.intp) * width + events["x"][inside]
        self.counts += np.bincount(pixel, minlength=height * width)


def summarize(
    chunks: Iterable[np.ndarray],
    *,
    width: int,
    height: int,
    mapper: Any = None,
    image: bool = False,
) -> EventSummary:
    """Totals over event chunks; with a ``GazeMapper``, the events inside the moving gaze window."""
    from darkread.edge.fovea import crop_along_track, origins_along_gaze

    summary = EventSummary()
    for events in chunks:
        summary.add(events)
        if image:
            summary.accumulate_image(events, width, height)
        if mapper is not None and events.shape[0]:
            origins = origins_along_gaze(events["t"], mapper.pixels_at, (width, height))
            summary.gaze_events += int(np.count_nonzero(np.isfinite(origins[:, 0])))
            summary.fovea_events += int(crop_along_track(events, origins).shape[0])
    return summary


def fovea_event_fraction(recording: Any) -> float:
    """Share of a recording's events inside the fovea window at the gaze of their own time: the
    one figure ``darkread inspect`` and ``darkread read`` report as "inside the fovea"."""
    from darkread.edge.gaze import GazeMapper

    reader = recording.reader()
    width, height = int(reader.header.width), int(reader.header.height)
    summary = summarize(reader, width=width, height=height, mapper=GazeMapper(recording.calibration, recording.gaze()))
    return summary.fovea_fraction




def inspect_path(
    path: str | Path,
    *,
    gaze: str | None = None,
    calibration: str | None = None,
    png: str | Path | None = None,
    chunk_bytes: int = DEFAULT_CHUNK_BYTES,
    progress: bool = True,
) -> dict[str, Any]:
    """The inspect report as a JSON-ready dict (see ``darkread inspect --help``)."""
    from darkread.edge.io.plausibility import TimeCheck, problems
    from darkread.edge.io.raw import RawReader
    from darkread.edge.io.recording import open_recording

    path = Path(path)
    is_recording = path.is_dir() or bool(gaze or calibration)
    recording = open_recording(path, gaze=gaze, calibration=calibration) if is_recording else None
    raw_path = recording.raw_path if recording else path
    if not raw_path.is_file():
        raise FileNotFoundError(f"{raw_path}: no such file")

    reader = RawReader(raw_path, chunk_bytes=chunk_bytes)
    header = reader.header
    width, height = int(header.width), int(header.height)
    mapper, track = None, None
    if recording is not None:
        from darkread.edge.gaze import GazeMapper

        track = recording.gaze()
        mapper = GazeMapper(recording.calibration, track)
        if (recording.calibration.width, recording.calibration.height) != (width, height):
            logger.warning(
                "calibration is for %dx%d but the RAW header says %dx%d",
                recording.calibration.width, recording.calibration.height, width, height,
            )

    time_check = TimeCheck()

    def chunks() -> Iterator[np.ndarray]:
        size = raw_path.stat().st_size
        with _progress(enabled=progress and size >= PROGRESS_MIN_BYTES, name=raw_path.name) as bar:
            for events in reader:
                bar.update(events.shape[0])
                time_check.add(events["t"])
                yield events

    summary = summarize(chunks(), width=width, height=height, mapper=mapper, image=png is not None)
    summary.triggers = int(reader.triggers.shape[0])  # the reader keeps the (few) triggers aside

    report = _report(path, header, summary, width, height)
    report["problems"] = problems(reader.stats, header.format, width, height, time_check)
    if recording is not None and track is not None:
        report.update(
            gaze_samples=len(track),
            gaze_valid_fraction=track.valid_fraction,
            gaze_schema=track.schema,
            gaze_event_fraction=summary.gaze_events / summary.events if summary.events else 0.0,
            fovea_event_fraction=summary.fovea_fraction,
            fovea_window_hw=[100, 200],
            clock_offset_us=mapper.clock_offset_us if mapper is not None else None,
        )
        if recording.meta:
            report["meta"] = recording.meta
    imu_path = None
    if recording is not None and recording.imu_path is not None:
        imu_path = _imu_path_px(recording)
        report["imu"] = _imu_report(recording)
    if png is not None:
        write_png(png, summary.counts, width, height, mapper, track, imu_path)
        report["png"] = str(png)
    return report


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


def _progress(*, enabled: bool, name: str) -> Any:
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(desc=f"inspect {name}", unit="ev", unit_scale=True, file=sys.stderr, leave=False)


def _imu_report(recording: Any) -> dict[str, Any]:
    """The IMU stream: samples, rate, duration, gaps, angular speed (deg/s) and how much of the events' time it covers."""
    from darkread.edge.imu_motion import ImuHeadMotion

    track = recording.imu()
    motion = ImuHeadMotion.of_track(track, recording.calibration)
    return {"file": recording.imu_path.name, "columns": "angular_velocity_{x,y,z}_device (rad/s, CPF), tracking_timestamp_us",
            **{k: round(v, 3) for k, v in motion.summary().items()}}


def _imu_path_px(recording: Any) -> np.ndarray | None:
    """[n, 2]: the principal point's scene shift the gyroscope predicts every 10 ms (for the picture)."""
    from darkread.edge.imu_motion import ImuHeadMotion, shift_px

    motion = ImuHeadMotion.of_track(recording.imu(), recording.calibration)
    span = motion.span_us
    if span is None:
        return None
    theta = motion.rotation_at(np.arange(span[0], span[1], 10_000))
    centre = (recording.calibration.cx, recording.calibration.cy)
    return np.asarray(centre) + shift_px(recording.calibration, centre, theta - theta[0])


def _report(path: Path, header: Any, s: EventSummary, width: int, height: int) -> dict[str, Any]:
    duration_us = (s.t_last_us - s.t_first_us) if s.events and s.t_first_us is not None and s.t_last_us is not None else 0
    return {
        "path": str(path),
        "format": str(header.format),
        "width": width,
        "height": height,
        "events": s.events,
        "on": s.on,
        "off": s.events - s.on,
        "t_first_us": s.t_first_us,
        "t_last_us": s.t_last_us,
        "duration_s": duration_us / 1e6,
        "event_rate_hz": s.events / (duration_us / 1e6) if duration_us > 0 else 0.0,
        "sum_t_us": s.sum_t_us,
        "sum_x": s.sum_x,
        "sum_y": s.sum_y,
        "triggers": s.triggers,
    }


def format_report(report: dict[str, Any]) -> str:
    lines = [
        f"{report['path']}",
        f"  sensor      {report['width']} x {report['height']}, {report['format']}",
        f"  duration    {report['duration_s']:.3f} s  (t {report['t_first_us']} .. {report['t_last_us']} us)",
        f"  events      {report['events']:,}  ({report['event_rate_hz'] / 1e3:,.1f} kev/s)",
        f"  ON / OFF    {report['on']:,} / {report['off']:,}"
        + (f"  ({report['on'] / report['events']:.1%} ON)" if report["events"] else ""),
        f"  triggers    {report['triggers']:,}",
    ]
    if "gaze_samples" in report:
        lines += [
            f"  gaze        {report['gaze_samples']} samples ({report['gaze_schema']}), "
            f"{report['gaze_valid_fraction']:.1%} valid",
            f"  gaze cover  {report['gaze_event_fraction']:.1%} of events have a usable gaze",
            f"  fovea       {report['fovea_event_fraction']:.1%} of events inside the 100x200 gaze window "
            f"({1 - report['fovea_event_fraction']:.1%} dropped)",
        ]
    if "imu" in report:
        imu = report["imu"]
        if imu.get("samples", 0) >= 2:
            lines.append(f"  IMU         {imu['file']}: {int(imu['samples']):,} samples at {imu['rate_hz']:.0f} Hz over "
                         f"{imu['duration_s']:.3f} s, {int(imu['gaps'])} gaps; angular speed median "
                         f"{imu['speed_deg_s_p50']:.2f} deg/s, p99 {imu['speed_deg_s_p99']:.2f} deg/s")
        else:
            lines.append(f"  IMU         {imu['file']}: {int(imu.get('samples', 0))} samples")
    if "png" in report:
        lines.append(f"  picture     {report['png']}")
    lines += [f"  PROBLEM     {problem}" for problem in report.get("problems", [])]
    return "\n".join(lines)


def write_png(
    out: str | Path, counts: np.ndarray | None, width: int, height: int, mapper: Any = None, track: Any = None,
    imu_path: np.ndarray | None = None,
) -> None:
    """Accumulated events (log-scaled grey) with the gaze window centres and a few windows drawn, and
    (magenta) the path of the principal point's scene shift the gyroscope predicts."""
    import cv2

    image = np.zeros((height, width), dtype=np.float64) if counts is None else counts.reshape(height, width)
    scale = np.log1p(image)
    top = np.percentile(scale[scale > 0], 99.5) if np.any(scale > 0) else 1.0
    grey = np.clip(scale / top * 255, 0, 255).astype(np.uint8)
    picture = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    if mapper is not None and track is not None and len(track):
        from darkread.edge.fovea import FoveaConfig, window_origins

        cfg = FoveaConfig()
        centres = mapper.pixels_at(track.t_us + mapper.clock_offset_us)
        good = np.isfinite(centres).all(axis=1)
        points = np.round(centres[good]).astype(np.int32)
        if points.shape[0] > 1:
            cv2.polylines(picture, [points.reshape(-1, 1, 2)], False, (0, 200, 255), 1, cv2.LINE_AA)
        origins = window_origins(centres[good], (width, height), cfg)
        for i in np.linspace(0, origins.shape[0] - 1, num=min(5, origins.shape[0])).astype(int):
            x0, y0 = int(origins[i, 0]), int(origins[i, 1])
            cv2.rectangle(picture, (x0, y0), (x0 + cfg.width - 1, y0 + cfg.height - 1), (0, 255, 0), 1)
    if imu_path is not None and np.isfinite(imu_path).all():
        cv2.polylines(picture, [np.round(imu_path).astype(np.int32).reshape(-1, 1, 2)], False, (255, 0, 255), 1, cv2.LINE_AA)
    if not cv2.imwrite(str(out), picture):
        raise ValueError(f"could not write {out} (use a .png name in an existing folder)")
