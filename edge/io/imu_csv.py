"""The head's rotation in the recording format: Project Aria MPS ``closed_loop_trajectory.csv``.

An optional file of a recording (``IMU_NAME``). Columns are those Aria's Machine Perception
Services export (``projectaria_tools`` data/gen1/mps_sample/trajectory), read by name; the edge uses
``tracking_timestamp_us`` (device clock, µs, the clock of ``general_eye_gaze.csv``) and
``angular_velocity_{x,y,z}_device`` (rad/s, in the device frame, ~1 kHz). In the recording format
the device frame is the CPF (``calibration.json``'s ``T_event_cpf`` rotates it into the event
camera); a real MPS file's angular velocities are rotated from Aria's device frame into the CPF
when the recording is made (the sample recording's README says how). The other columns (pose,
velocity, gravity, quality) are read when present and not needed.
"""

from __future__ import annotations

import csv
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.errors import ImuCsvError

IMU_NAME = "closed_loop_trajectory.csv"
TIMESTAMP = "tracking_timestamp_us"
ANGULAR_VELOCITY = ("angular_velocity_x_device", "angular_velocity_y_device", "angular_velocity_z_device")

MPS_COLUMNS: tuple[str, ...] = (
    "graph_uid",
    TIMESTAMP,
    "utc_timestamp_ns",
    "tx_world_device",
    "ty_world_device",
    "tz_world_device",
    "qx_world_device",
    "qy_world_device",
    "qz_world_device",
    "qw_world_device",
    "device_linear_velocity_x_device",
    "device_linear_velocity_y_device",
    "device_linear_velocity_z_device",
    *ANGULAR_VELOCITY,
    "gravity_x_world",
    "gravity_y_world",
    "gravity_z_world",
    "quality_score",
)
"""The header of MPS ``closed_loop_trajectory.csv`` (geo columns absent), in its order."""

MAX_RATE_HZ = 10_000.0  # a faster stream is no IMU we know (Aria's run at 800 Hz and 1 kHz)
MAX_ANGULAR_SPEED_RAD_S = 35.0  # +-2000 deg/s: the widest range of a MEMS gyroscope


@dataclass(frozen=True)
class ImuTrack:
    """Angular velocity samples on the device clock: ``t_us`` int64 [n] increasing, ``omega`` float64 [n, 3]."""

    t_us: np.ndarray
    omega: np.ndarray  # rad/s, device frame (CPF axes: x to the wearer's left, y up, z forward)

    def __len__(self) -> int:
        return int(self.t_us.shape[0])

    @property
    def rate_hz(self) -> float:
        """The median sample rate (0 with fewer than two samples)."""
        if len(self) < 2:
            return 0.0
        return 1e6 / float(np.median(np.diff(self.t_us)))

    @property
    def duration_s(self) -> float:
        return 0.0 if len(self) < 2 else float(self.t_us[-1] - self.t_us[0]) * 1e-6


def read_imu_csv(path: str | Path) -> ImuTrack:
    """Read an MPS ``closed_loop_trajectory.csv``; ``ImuCsvError`` names the file, line and problem."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            first = next(csv.reader(fh), None)
    except UNREADABLE as exc:
        raise _unreadable(path, exc) from exc
    if not first:
        raise ImuCsvError(f"{path}, line 1: empty file, expected a header row with {TIMESTAMP}")
    header = [name.strip() for name in first]
    missing = [name for name in (TIMESTAMP, *ANGULAR_VELOCITY) if name not in header]
    if missing:
        raise ImuCsvError(f"{path}, line 1: missing column(s) {', '.join(missing)} "
                          "(expected Aria MPS closed_loop_trajectory.csv)")
    columns = [header.index(name) for name in (TIMESTAMP, *ANGULAR_VELOCITY)]
    try:  # numpy's compiled parser, one pass; anything it cannot read is read again row by row
        data = path.read_bytes()
        rows = data.count(b"\n") + (not data.endswith(b"\n"))
        if data.count(b",") != rows * (len(header) - 1):  # a row with more or fewer cells than the header
            raise ValueError("ragged rows")
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # (an empty body warns)
            samples = np.loadtxt(io.StringIO(data.decode("utf-8")), delimiter=",", skiprows=1, usecols=columns, ndmin=1,
                                 dtype=[("t", np.int64), ("omega", np.float64, (3,))])
        t_us, omega = np.ascontiguousarray(samples["t"]), np.ascontiguousarray(samples["omega"])
    except (ValueError, UserWarning):
        t_us, omega = _read_rows(path, header, columns)
    return _checked(path, t_us, omega)


def _read_rows(path: Path, header: list[str], columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The samples read row by row, each row checked: the first that is wrong is named."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            body = list(csv.reader(fh))[1:]
    except UNREADABLE as exc:  # (a bad byte past the header)
        raise _unreadable(path, exc) from exc
    if not body:
        raise ImuCsvError(f"{path}: no samples after the header")
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise ImuCsvError(f"{path}, line {i + 2}: {len(row)} cells, the header has {len(header)}")
        try:
            int(row[columns[0]]), [float(row[k]) for k in columns[1:]]
        except ValueError:
            raise ImuCsvError(f"{path}, line {i + 2}: {TIMESTAMP} must be an integer and the angular velocities "
                              f"numbers, got {[row[k] for k in columns]}") from None
    cells = list(zip(*body))  # (a column per cell of the header)
    t_us = np.array(cells[columns[0]]).astype(np.int64)
    return t_us, np.stack([np.array(cells[k]).astype(np.float64) for k in columns[1:]], axis=1)


UNREADABLE = (OSError, UnicodeDecodeError, csv.Error)


def _unreadable(path: Path, exc: Exception) -> ImuCsvError:
    return ImuCsvError(f"{path}: cannot read the head-motion CSV: {exc}")


def _checked(path: Path, t_us: np.ndarray, omega: np.ndarray) -> ImuTrack:
    """The track, once its samples are plausible: finite rates in rad/s, increasing microseconds."""
    if t_us.shape[0] == 0:
        raise ImuCsvError(f"{path}: no samples after the header")
    wrong = ~np.isfinite(omega).all(axis=1) | (np.abs(np.nan_to_num(omega, nan=0.0)).max(axis=1) > MAX_ANGULAR_SPEED_RAD_S)
    if wrong.any():
        i = int(np.flatnonzero(wrong)[0])
        raise ImuCsvError(f"{path}, line {i + 2}: angular velocity {omega[i].tolist()} rad/s is not finite or "
                          f"beyond {MAX_ANGULAR_SPEED_RAD_S:g} rad/s (degrees instead of radians?)")
    steps = np.diff(t_us)
    if steps.size and (steps <= 0).any():
        bad = int(np.flatnonzero(steps <= 0)[0])
        raise ImuCsvError(f"{path}, line {bad + 3}: {TIMESTAMP} {int(t_us[bad + 1])} does not increase "
                          f"(previous {int(t_us[bad])})")
    if steps.size and 1e6 / float(np.median(steps)) > MAX_RATE_HZ:
        raise ImuCsvError(f"{path}: {1e6 / float(np.median(steps)):.0f} samples a second: {TIMESTAMP} must be "
                          "microseconds (nanoseconds?)")
    return ImuTrack(t_us, omega)


def write_imu_csv(path: str | Path, t_us: np.ndarray, omega: np.ndarray, q_world_device: np.ndarray, *,
                  graph_uid: str, utc_offset_ns: int, gravity_world: tuple[float, float, float] = (0.0, 0.0, -9.81),
                  quality_score: float = 1.0) -> None:
    """Write an MPS-shaped ``closed_loop_trajectory.csv``: ``t_us`` device clock [n], ``omega`` rad/s [n, 3]
    in the device frame, ``q_world_device`` [n, 4] (x, y, z, w) the device's orientation; translation
    and linear velocity are written as zeros (not modelled), ``gravity_world`` in every row (MPS: world z up)."""
    t_us = np.asarray(t_us, np.int64)
    omega = np.asarray(omega, np.float64).reshape(-1, 3)
    q = np.asarray(q_world_device, np.float64).reshape(-1, 4)
    if not t_us.shape[0] == omega.shape[0] == q.shape[0]:
        raise ValueError("write_imu_csv: t_us, omega and q_world_device must have one row per sample")
    utc_ns = t_us * 1000 + int(utc_offset_ns)
    lines = [",".join(MPS_COLUMNS)]
    fmt = "{},{},{},0.000000,0.000000,0.000000,{:.9f},{:.9f},{:.9f},{:.9f},0.000000,0.000000,0.000000,{:.6f},{:.6f},{:.6f},{:.6f},{:.6f},{:.6f},{:g}"
    lines += [fmt.format(graph_uid, int(t), int(u), *qq, *w, *gravity_world, quality_score)
              for t, u, qq, w in zip(t_us.tolist(), utc_ns.tolist(), q.tolist(), omega.tolist())]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
