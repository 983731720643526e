"""Eye-gaze CSVs: every MPS schema by column name, conventions, malformed input, write/read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from darkread.edge.errors import GazeCsvError
from darkread.edge.gaze import gaze_point_cpf
from darkread.edge.io.gaze_csv import (
    VERGENCE_COLUMNS,
    elevation_to_projection_pitch,
    read_gaze_csv,
    spherical_directions,
    write_gaze_csv,
)

ARIA_FILES = {
    "gen1/mps_sample/eye_gaze/eyegaze.csv": ("gen1_v1", 123),
    "gen1/mps_sample/eye_gaze/generalized_eye_gaze.csv": ("gen1_v2", 123),
    "gen1/mps_sample/eye_gaze_vergence/generalized_gaze.csv": ("gen1_vergence", 123),
    "gen1/aria_digital_twin_test_data/eyegaze.csv": ("gen1_v1", 6),
    "gen2/mps_sample/eye_gaze/general_eye_gaze.csv": ("gen2", 5),
    "gen2/mps_sample/eye_gaze/personalized_eye_gaze.csv": ("gen2", 5),
}
VERGENCE = "gen1/mps_sample/eye_gaze_vergence/generalized_gaze.csv"


@pytest.mark.shared
@pytest.mark.parametrize("name", sorted(ARIA_FILES))
def test_reads_every_aria_schema(aria_dir: Path, name: str) -> None:
    schema, rows = ARIA_FILES[name]
    track = read_gaze_csv(aria_dir / name)
    assert track.schema == schema
    assert len(track) == rows
    assert np.all(np.diff(track.t_us) >= 0)
    assert track.t_us.dtype == np.int64 and track.depth_m.dtype == np.float64
    for column in (track.yaw_rad, track.pitch_rad, track.depth_m, track.valid):
        assert column.shape == (rows,)
    assert np.allclose(np.linalg.norm(track.directions_cpf(), axis=1), 1.0)
    assert track.valid.mean() > 0.9


@pytest.mark.shared
def test_v1_and_v2_columns_in_different_order_give_the_same_track(aria_dir: Path) -> None:
    v1 = read_gaze_csv(aria_dir / "gen1/mps_sample/eye_gaze/eyegaze.csv")
    v2 = read_gaze_csv(aria_dir / "gen1/mps_sample/eye_gaze/generalized_eye_gaze.csv")
    assert np.array_equal(v1.t_us, v2.t_us)
    assert np.allclose(v1.yaw_rad, v2.yaw_rad) and np.allclose(v1.pitch_rad, v2.pitch_rad)
    assert np.all(np.isnan(v1.depth_m)) and np.all(np.isnan(v2.depth_m))  # empty depth = unknown
    assert v1.session_uid is None and v2.session_uid == "8d34a429-0122-49a7-9eec-751da9d37d9f"


@pytest.mark.shared
def test_zero_depth_is_unknown(aria_dir: Path) -> None:
    track = read_gaze_csv(aria_dir / "gen1/aria_digital_twin_test_data/eyegaze.csv")
    assert np.isnan(track.depth_m[0])  # written as 0 in the file
    assert track.depth_m[1] == pytest.approx(0.511755)


@pytest.mark.shared
def test_vergence_combined_yaw_and_cross_check_points(aria_dir: Path) -> None:
    # Reference rows from projectaria-tools 2.3.0 (reference notes aria-gaze.md, section 3).
    track = read_gaze_csv(aria_dir / VERGENCE)
    expected = {
        0: (148502622, 0.78780, -0.02056, 1.5981, (1.1326, -0.0232, 1.1272)),
        10: (149502622, 0.18078, -0.26888, 0.9214, (0.1599, -0.2411, 0.8748)),
        100: (158502622, -0.06585, -0.75064, 1.2938, (-0.0623, -0.8815, 0.9450)),
    }
    for row, (t, yaw, pitch, depth, point) in expected.items():
        assert track.t_us[row] == t
        assert track.yaw_rad[row] == pytest.approx(yaw, abs=1e-5)
        assert track.pitch_rad[row] == pytest.approx(pitch, abs=1e-5)
        assert track.depth_m[row] == pytest.approx(depth, abs=1e-4)
        p = gaze_point_cpf(track.yaw_rad[row : row + 1], track.pitch_rad[row : row + 1], track.depth_m[row : row + 1])
        assert np.allclose(p[0], point, atol=1e-4)


@pytest.mark.shared
def test_wide_confidence_bounds_mark_rows_invalid(aria_dir: Path) -> None:
    track = read_gaze_csv(aria_dir / VERGENCE)
    assert track.bounds_width_rad is not None
    wide = track.bounds_width_rad > 0.5
    assert wide.any()  # Meta's sample has a few tracking failures (bounds up to ~1.3 rad)
    assert np.array_equal(track.valid, ~wide)
    assert read_gaze_csv(aria_dir / VERGENCE, max_bounds_width_rad=2.0).valid.all()


@pytest.mark.shared
def test_gen2_elevation_is_converted_and_depth_recovered_from_the_eye_rays(aria_dir: Path) -> None:
    track = read_gaze_csv(aria_dir / "gen2/mps_sample/eye_gaze/general_eye_gaze.csv")
    assert track.yaw_rad[0] == pytest.approx(0.07778, abs=1e-5)
    assert track.depth_m[0] == pytest.approx(0.588, abs=1e-3)
    point = gaze_point_cpf(track.yaw_rad[:1], track.pitch_rad[:1], track.depth_m[:1])[0]
    # projectaria-tools' spatial gaze point for this row; the file's pitch is asin(y/|p|).
    assert np.allclose(point, (0.0427, -0.2099, 0.5467), atol=1e-3)
    assert np.arcsin(point[1] / np.linalg.norm(point)) == pytest.approx(-0.36553, abs=1e-4)


def test_elevation_to_projection_pitch_matches_the_direction_vector() -> None:
    yaw = np.array([0.0, 0.1, 0.3, 0.5, -0.4])
    elevation = np.array([0.2, -0.1, -0.35, -0.5, 0.3])
    d = spherical_directions(yaw, elevation)
    assert np.allclose(np.arctan2(d[:, 0], d[:, 2]), yaw)
    assert np.allclose(elevation_to_projection_pitch(yaw, elevation), np.arctan2(d[:, 1], d[:, 2]))


@pytest.mark.shared
def test_sample_recording_gaze(shared_sample_recording: Path) -> None:
    track = read_gaze_csv(shared_sample_recording / "general_eye_gaze.csv")
    assert (track.schema, len(track)) == ("gen1_vergence", 211)
    assert track.session_uid == "34677054-7ac6-44d4-9be6-62f5046b0c3a"
    assert track.valid.all()
    assert np.all((track.depth_m > 0.3) & (track.depth_m <= 4.0))
    tc = (np.tan(-0.07754892855882645) + np.tan(-0.20317938923835754)) / 2
    assert track.yaw_rad[0] == pytest.approx(np.arctan(tc))


def test_write_then_read_round_trip(tmp_path: Path) -> None:
    t = np.array([1000, 17_000, 33_500], dtype=np.int64)
    left, right = np.array([0.1, 0.0, -0.2]), np.array([0.05, -0.04, -0.25])
    pitch, depth = np.array([0.01, -0.02, 0.03]), np.array([0.45, np.nan, 0.5])
    path = tmp_path / "general_eye_gaze.csv"
    write_gaze_csv(path, t, left, right, pitch, depth, bounds_rad=0.05, session_uid="abc")
    header = path.read_text().splitlines()[0].split(",")
    assert tuple(header) == VERGENCE_COLUMNS
    track = read_gaze_csv(path)
    assert track.schema == "gen1_vergence" and track.session_uid == "abc"
    assert np.array_equal(track.t_us, t)
    assert np.allclose(track.yaw_rad, np.arctan((np.tan(left) + np.tan(right)) / 2))
    assert np.array_equal(track.pitch_rad, pitch)  # repr() keeps every bit
    assert np.isnan(track.depth_m[1]) and track.depth_m[2] == 0.5
    assert np.allclose(track.bounds_width_rad, 0.1)


def test_unsorted_rows_are_sorted(tmp_path: Path) -> None:
    path = tmp_path / "g.csv"
    write_gaze_csv(path, np.array([30, 10, 20]), np.zeros(3), np.zeros(3), np.array([0.3, 0.1, 0.2]), np.ones(3))
    track = read_gaze_csv(path)
    assert track.t_us.tolist() == [10, 20, 30]
    assert np.allclose(track.pitch_rad, [0.1, 0.2, 0.3])


def test_nan_angles_are_invalid_rows(tmp_path: Path) -> None:
    path = tmp_path / "g.csv"
    path.write_text("tracking_timestamp_us,yaw_rads_cpf,pitch_rads_cpf,depth_m\n1,0.1,0.2,\n2,nan,0.1,\n3,,0.1,0.5\n")
    track = read_gaze_csv(path)
    assert track.valid.tolist() == [True, False, False]


@pytest.mark.parametrize(
    ("content", "line", "fragment"),
    [
        ("", 1, "empty file"),
        ("tracking_timestamp_us,pitch_rads_cpf,depth_m\n1,0.1,\n", 1, "yaw_rads_cpf"),
        ("tracking_timestamp_us,yaw_rads_cpf,pitch_rads_cpf\n1,0.1,0.2\n2,zero,0.1\n", 3, "'zero' is not a number"),
        ("tracking_timestamp_us,yaw_rads_cpf,pitch_rads_cpf\n1.5,0.1,0.2\n", 2, "integer timestamp"),
        ("tracking_timestamp_us,yaw_rads_cpf,pitch_rads_cpf\n1,0.1,0.2\n2,0.1\n", 3, "2 cells"),
    ],
)
def test_malformed_csv_names_file_and_line(tmp_path: Path, content: str, line: int, fragment: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(GazeCsvError) as info:
        read_gaze_csv(path)
    assert str(path) in str(info.value)
    assert f"line {line}" in str(info.value)
    assert fragment in str(info.value)


@pytest.mark.shared
@pytest.mark.parametrize("name", sorted(ARIA_FILES))
def test_cross_check_with_projectaria_tools(aria_dir: Path, name: str) -> None:
    """Optional oracle; install with `.venv/bin/pip install --no-deps projectaria-tools==2.3.0`
    (~145 MB; the full install with dependencies is ~1.6 GB, so it is in no extra)."""
    mps = pytest.importorskip("projectaria_tools.core.mps")
    from projectaria_tools.core.mps.utils import get_eyegaze_point_at_depth

    theirs = mps.read_eyegaze(str(aria_dir / name))
    ours = read_gaze_csv(aria_dir / name)
    assert len(theirs) == len(ours)
    t_us = np.array([int(g.tracking_timestamp.total_seconds() * 1e6 + 0.5) for g in theirs])
    assert np.array_equal(t_us, ours.t_us)
    depth = np.array([g.depth for g in theirs], dtype=np.float64)
    assert np.allclose(np.where(depth > 0, depth, np.nan), ours.depth_m, atol=1e-5, equal_nan=True)
    yaw = np.array([g.yaw for g in theirs])
    assert np.allclose(yaw, ours.yaw_rad, atol=1e-6)
    ours_points = gaze_point_cpf(ours.yaw_rad, ours.pitch_rad, np.ones(len(ours)))
    if ours.schema == "gen2":
        # Their point-at-depth helper reads the Gen2 elevation as a projection pitch; compare with
        # their spatial gaze point (closest approach of the eye rays) instead.
        spatial = np.array([g.spatial_gaze_point_in_cpf for g in theirs])
        ours_points = gaze_point_cpf(ours.yaw_rad, ours.pitch_rad, ours.depth_m)
        assert np.allclose(spatial, ours_points, atol=1e-3)
    else:
        theirs_points = np.array([get_eyegaze_point_at_depth(g.yaw, g.pitch, 1.0) for g in theirs])
        assert np.allclose(theirs_points, ours_points, atol=1e-6)
