"""The recording format's IMU stream (MPS closed_loop_trajectory.csv): written, read, and refused when bad."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from darkread.edge.errors import ImuCsvError, RecordingError
from darkread.edge.io.imu_csv import ANGULAR_VELOCITY, MPS_COLUMNS, TIMESTAMP, read_imu_csv, write_imu_csv

# the header of projectaria_tools' data/gen1/mps_sample/trajectory/closed_loop_trajectory_geo_missing.csv
MPS_SAMPLE_HEADER = ("graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,"
                     "qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,"
                     "device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,"
                     "angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,"
                     "quality_score")
MPS_SAMPLE_ROW = ("ea7288b8-b6a0-012d-8156-257aba6bd796,149202610,1686767222002923694,0.000292,-0.006405,0.000467,"
                  "0.500638545,0.496952726,-0.477400195,0.523916109,0.038913,-0.322935,0.242351,-0.054750,0.052271,"
                  "-0.064212,0.000000,0.000000,-9.810000,0.5")


def _written(path: Path, n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    t = 1_000_000 + np.arange(n, dtype=np.int64) * 1000
    omega = np.random.default_rng(0).normal(0, 0.1, (n, 3))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_imu_csv(path, t, omega, q, graph_uid="g", utc_offset_ns=0)
    return t, omega


def test_our_header_is_mps_and_round_trips(tmp_path: Path) -> None:
    assert ",".join(MPS_COLUMNS) == MPS_SAMPLE_HEADER
    t, omega = _written(tmp_path / "imu.csv")
    track = read_imu_csv(tmp_path / "imu.csv")
    assert np.array_equal(track.t_us, t)
    assert np.allclose(track.omega, omega, atol=5e-7)  # written with 6 decimals, as MPS does
    assert track.rate_hz == pytest.approx(1000.0) and track.duration_s == pytest.approx(0.049)


def test_reads_an_mps_file_by_column_name(tmp_path: Path) -> None:
    path = tmp_path / "closed_loop_trajectory.csv"
    second = MPS_SAMPLE_ROW.replace("149202610", "149203459")
    path.write_text(f"{MPS_SAMPLE_HEADER},geo_available\n{MPS_SAMPLE_ROW},0\n{second},0\n")
    track = read_imu_csv(path)
    assert track.t_us.tolist() == [149202610, 149203459]
    assert track.omega[0].tolist() == [-0.054750, 0.052271, -0.064212]


@pytest.mark.parametrize(("body", "message"), [
    ("", "line 1: empty file"),
    ("tracking_timestamp_us,angular_velocity_x_device\n1,0\n", "missing column(s) angular_velocity_y_device"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n", "no samples after the header"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,0,0\n1000,0,0,0\n", "line 3: tracking_timestamp_us 1000 does not increase"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,0\n", "line 2: 3 cells, the header has 4"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,0,0\n2000,0,0,0,0\n", "line 3: 5 cells, the header has 4"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,a,0,0\n", "line 2: tracking_timestamp_us must be an integer"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,90,0\n", "line 2: angular velocity [0.0, 90.0, 0.0] rad/s"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,nan,0\n", "is not finite"),
    (f"{TIMESTAMP},{','.join(ANGULAR_VELOCITY)}\n1000,0,0,0\n1001,0,0,0\n1002,0,0,0\n", "nanoseconds?"),
])
def test_a_bad_file_is_one_clear_error(tmp_path: Path, body: str, message: str) -> None:
    path = tmp_path / "closed_loop_trajectory.csv"
    path.write_text(body)
    with pytest.raises(ImuCsvError) as caught:
        read_imu_csv(path)
    assert message in str(caught.value) and str(path) in str(caught.value)
    assert isinstance(caught.value, RecordingError) and "\n" not in str(caught.value)


def test_a_file_numpy_cannot_parse_is_read_row_by_row_to_the_same_track(tmp_path: Path) -> None:
    t, omega = _written(tmp_path / "imu.csv")
    text = (tmp_path / "imu.csv").read_text()
    (tmp_path / "quoted.csv").write_text(text.replace(f",{t[3]},", f',"{t[3]}",', 1))  # valid CSV, quoted cell
    plain, quoted = read_imu_csv(tmp_path / "imu.csv"), read_imu_csv(tmp_path / "quoted.csv")
    assert np.array_equal(plain.t_us, quoted.t_us) and np.array_equal(plain.omega, quoted.omega)


def test_an_unreadable_file(tmp_path: Path) -> None:
    path = tmp_path / "closed_loop_trajectory.csv"
    path.write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(ImuCsvError, match="cannot read the head-motion CSV"):
        read_imu_csv(path)
    # a bad byte far past the header (the header row read alone is fine): still named with the file
    _written(path, n=400)
    path.write_bytes(path.read_bytes() + b"1,2,\xff\n")
    with pytest.raises(ImuCsvError, match="cannot read the head-motion CSV") as caught:
        read_imu_csv(path)
    assert str(path) in str(caught.value)
