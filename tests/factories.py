"""Test data factories (import as ``from factories import ...``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE, make_events


def random_events(
    n: int, width: int = 1280, height: int = 720, t0: int = 0, rate_hz: float = 1e6, seed: int = 0
) -> np.ndarray:
    """Random time-sorted events (a tonic-style factory)."""
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=EVENT_CD_DTYPE)
    ev["x"] = rng.integers(0, width, n)
    ev["y"] = rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    ev["t"] = t0 + np.sort(rng.integers(0, max(1, int(n / rate_hz * 1e6)), n))
    return ev


def sum_bins_model(path: Path, shape: tuple[int, int, int] | None = None) -> Path:
    """A stand-in reconstruction model (logits = sum over the time bins) of input ``shape``
    (bins, height, width; default the shipped model's)."""
    import pytest

    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    from darkread.edge.voxel import VoxelConfig

    bins, height, width = shape or VoxelConfig().shape
    x = helper.make_tensor_value_info("voxel", TensorProto.FLOAT, ["batch", bins, height, width])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["batch", 1, height, width])
    axes = helper.make_tensor("axes", TensorProto.INT64, [1], [1])
    node = helper.make_node("ReduceSum", ["voxel", "axes"], ["logits"], keepdims=1)
    model = helper.make_model(
        helper.make_graph([node], "sum_bins", [x], [y], initializer=[axes]),
        opset_imports=[helper.make_opsetid("", 17)],
    )
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


def synthetic_recording(root: Path, n_events: int = 30_000, box_xywh: tuple[int, int, int, int] = (540, 310, 200, 100)) -> Path:
    """A recording directory whose events all fall in one box, the gaze fixed on the sensor centre."""
    from darkread.edge.io.calibration import Calibration, save_calibration
    from darkread.edge.io.gaze_csv import write_gaze_csv
    from darkread.edge.io.raw import write_raw

    x0, y0, w, h = box_xywh
    root.mkdir()
    ev = random_events(n_events, width=w, height=h, t0=1_000, rate_hz=100_000, seed=7)
    ev["x"] += x0
    ev["y"] += y0
    _, keep = np.unique(np.stack([ev["t"], ev["y"].astype(np.int64), ev["x"].astype(np.int64)]), axis=1, return_index=True)
    write_raw(root / "events.raw", ev[np.sort(keep)])
    t = np.arange(0, 400_000, 16_667)
    zeros = np.zeros(t.shape[0])
    write_gaze_csv(root / "general_eye_gaze.csv", t, zeros, zeros, zeros, np.full(t.shape[0], 0.45))
    save_calibration(root / "calibration.json", Calibration(
        width=1280, height=720, fx=600.0, fy=600.0, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
        T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=0,
    ))
    (root / "text.txt").write_text("synthetic")
    (root / "meta.json").write_text("{}")
    return root


def pixel_at(lookup, t_event_us: int) -> tuple[float, float] | None:
    """The gaze pixel a ``GazeLookup`` gives at an event time (None without a gaze on the sensor)."""
    sample = lookup.at(t_event_us)
    return None if sample is None else sample.pixel


def angles_at(lookup, t_event_us: int) -> tuple[float, float] | None:
    """The gaze angles (yaw, pitch) a ``GazeLookup`` gives at an event time."""
    sample = lookup.at(t_event_us)
    return None if sample is None else sample.angles


def pangram_session(motion: str, lux: float = 1000.0):
    """A short synthetic reading of a two-line pangram (seed 5, DejaVu Sans, x-height 11 px)."""
    from darkread.lab.synth.rgb_camera import session_for
    from darkread.models.synth.recording import RecordingSpec

    spec = RecordingSpec(lux=lux, motion=motion, kind="pangram", seconds=2.0, seed=5, font="DejaVu Sans",
                         xheight_px=11.0, n_lines=2, line_chars=24)
    return session_for(spec)


def under_light(session, lux: float):
    """The same session lit by ``lux``."""
    from dataclasses import replace

    return replace(session, scene=replace(session.scene, lux=lux))


def moving_strokes(velocity_px_s: tuple[float, float], span_ms: float = 30.0, seed: int = 0, noise_share: float = 0.0,
                   origin: tuple[int, int] = (540, 310), sensor: tuple[int, int] = (1280, 720)):
    """Events of random 5-px strokes around the 100x200 window at ``origin`` moving rigidly at ``velocity_px_s`` for
    ``span_ms`` (each stroke pixel fires now and then where it is at that time), plus a share of
    uniform noise events."""
    rng = np.random.default_rng(seed)
    base = rng.uniform([origin[0] - 60, origin[1] - 60], [origin[0] + 260, origin[1] + 160], (300, 2))
    along = np.arange(5)[:, None, None] * rng.choice([[1, 0], [0, 1]], 300)[None, :, :]
    points = (base[None, :, :] + along).reshape(-1, 2)
    n = int(points.shape[0] * span_ms / 4)  # each pixel fires every ~4 ms
    t = np.sort(rng.uniform(0, span_ms * 1000, n)).astype(np.int64) + 1_000_000
    which = rng.integers(0, points.shape[0], n)
    xy = points[which] + np.outer((t - t[0]) / 1e6, velocity_px_s)
    if noise_share:
        k = int(n * noise_share)
        noise_xy = rng.uniform([origin[0] - 60, origin[1] - 60], [origin[0] + 260, origin[1] + 160], (k, 2))
        xy = np.concatenate([xy, noise_xy])
        t = np.concatenate([t, rng.integers(int(t[0]), int(t[-1]) + 1, k)])
        order = np.argsort(t, kind="stable")
        xy, t = xy[order], t[order]
    xy = np.rint(xy).astype(int)
    keep = (xy[:, 0] >= 0) & (xy[:, 0] < sensor[0]) & (xy[:, 1] >= 0) & (xy[:, 1] < sensor[1])
    return make_events(xy[keep, 0], xy[keep, 1], rng.integers(0, 2, int(keep.sum())), t[keep])
