"""Synthetic calibration captures: a marker board flashing on a screen, seen by the event camera
(through the ESIM sensor model of ``sensor.py``) and by the glasses' RGB camera.

The screen switches between the board and a blank white page at known times. The glasses are
held still in a few poses; at each pose the board appears and disappears a few times. The event
camera fires a burst at every switch; the RGB camera takes frames at a fixed rate on the device
clock, and a frame whose exposure spans a switch shows a blend of the two pictures.

The board and anything around the screen are planes: each pixel's undistorted ray meets the
screen plane at a point given by a homography of the ray, so the picture is exact under any lens
model. Per pose only the pixels that see the screen are simulated; the rest of the sensor gets
the sensor's noise rates (``background_events``).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from darkread.edge.calibrate.cameras import Camera, Fisheye624Camera
from darkread.edge.calibrate.markers import BoardSpec, save_board
from darkread.edge.events import EVENT_CD_DTYPE, TRIGGER_DTYPE
from darkread.edge.io.calibration import Calibration, save_calibration
from darkread.edge.io.intrinsics import RECTIFIED, Intrinsics
from darkread.edge.io.raw import write_raw
from darkread.image_codec import write_png
from darkread.models.synth.camera import (
    SENSOR_WH,
    random_calibration,
    region_rays,
    rotation_xyz,
)
from darkread.models.synth.sensor import (
    EventSensor,
    SensorParams,
    background_events,
    concat_events,
)

RGB_FRAMES_NAME = "rgb_frames.csv"
SESSION_US = 12_000_000  # captures of one session start and end within this span (start_s + duration)


@dataclass
class ScreenTarget:
    """A board shown on a screen with a white margin; luminances in lux-equivalent at the sensor."""

    spec: BoardSpec
    px_per_m: float = 2000.0
    margin_m: float = 0.02
    white_lux: float = 250.0
    black_fraction: float = 0.3  # screen black level relative to white (a dimmed flash keeps event counts small)
    surround: float = 0.04  # what lies around the screen, relative to white
    _texture: np.ndarray | None = field(default=None, repr=False)

    @property
    def texture(self) -> np.ndarray:
        """Board picture with its margin, float32 0..1, lightly blurred (display and optics)."""
        if self._texture is None:
            board = self.spec.image(self.px_per_m).astype(np.float32) / 255.0
            m = round(self.margin_m * self.px_per_m)
            tex = np.pad(board, m, constant_values=1.0)
            tex = self.black_fraction + (1.0 - self.black_fraction) * tex
            self._texture = cv2.GaussianBlur(tex, (0, 0), 0.6).astype(np.float32)
        return self._texture

    def corners_m(self) -> np.ndarray:
        """Screen area (board plus margin) corners in the board frame, (4, 3)."""
        w, h = self.spec.size_m
        m = self.margin_m
        return np.array([[-m, -m, 0], [w + m, -m, 0], [w + m, h + m, 0], [-m, h + m, 0]], dtype=np.float64)

    def render(self, rays: np.ndarray, shape: tuple[int, int], T_cam_board: np.ndarray, shown: float) -> np.ndarray:
        """Irradiance (float32 ``shape``) of pixels with normalised rays ``rays`` [h*w, 2].

        ``shown`` in [0, 1] blends the blank screen (0) and the board (1), as an exposure that
        spans a switch sees it.
        """
        return self.blend(*self.render_pair(rays, shape, T_cam_board), shown)

    def render_pair(self, rays: np.ndarray, shape: tuple[int, int], T_cam_board: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(board shown, blank screen) irradiance images; any exposure is a blend of the two."""
        board, outside = sample_plane(self.texture, self.px_per_m, self.margin_m, rays, shape, T_cam_board)
        lux = np.float32(self.white_lux)
        shown = np.where(outside, np.float32(self.surround), board) * lux
        blank = np.where(outside, np.float32(self.surround), np.float32(1.0)) * lux
        return shown.astype(np.float32), blank.astype(np.float32)

    @staticmethod
    def blend(shown_image: np.ndarray, blank_image: np.ndarray, shown: float) -> np.ndarray:
        return (np.float32(shown) * shown_image + np.float32(1.0 - shown) * blank_image).astype(np.float32)


def sample_plane(
    texture: np.ndarray, px_per_m: float, margin_m: float, rays: np.ndarray, shape: tuple[int, int], T_cam_plane: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(texture value, outside mask) seen along each ray; texel (0, 0) covers plane point -margin.

    A pixel's ray meets the plane z = 0 of ``T_cam_plane`` at a point that is a homography of the
    ray, so this is exact under any lens model (the rays carry the distortion).
    """
    H = np.column_stack([T_cam_plane[:3, 0], T_cam_plane[:3, 1], T_cam_plane[:3, 3]])
    inv = np.linalg.inv(H).astype(np.float32)
    rx = rays[:, 0].astype(np.float32).reshape(shape)
    ry = rays[:, 1].astype(np.float32).reshape(shape)
    w = inv[2, 0] * rx + inv[2, 1] * ry + inv[2, 2]
    behind = w <= 0
    w = np.where(behind, np.float32(1.0), w)
    scale, offset = np.float32(px_per_m), np.float32(margin_m * px_per_m - 0.5)
    u = (inv[0, 0] * rx + inv[0, 1] * ry + inv[0, 2]) / w * scale + offset
    v = (inv[1, 0] * rx + inv[1, 1] * ry + inv[1, 2]) / w * scale + offset
    value = cv2.remap(texture, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    return value, (value < 0) | behind


def look_at_board(target: ScreenTarget, distance_m: float, tilt_deg: tuple[float, float, float], offset_m: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """``T_cam_board`` with the board centre ``distance_m`` ahead (shifted by ``offset_m``), tilted."""
    w, h = target.spec.size_m
    R = rotation_xyz(*np.radians(tilt_deg))
    T = np.eye(4)
    T[:3, :3] = R
    centre = np.array([offset_m[0], offset_m[1], distance_m])
    T[:3, 3] = centre - R @ np.array([w / 2, h / 2, 0.0])
    return T


def screen_region(calib: Calibration, target: ScreenTarget, T_event_board: np.ndarray, margin_px: int = 6) -> tuple[int, int, int, int]:
    """(x0, y0, w, h): the sensor pixels that see the screen (dense sampling of its outline)."""
    c = target.corners_m()
    s = np.linspace(0, 1, 33)[:, None]
    outline = np.concatenate([c[i] + s * (c[(i + 1) % 4] - c[i]) for i in range(4)])
    pts = outline @ T_event_board[:3, :3].T + T_event_board[:3, 3]
    uv = calib.project(pts)
    uv = uv[np.isfinite(uv).all(axis=1)]
    if uv.size == 0:
        raise ValueError("the screen is not in front of the event camera")
    w, h = SENSOR_WH
    x0, y0 = np.maximum(np.floor(uv.min(axis=0)) - margin_px, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(uv.max(axis=0)) + margin_px + 1, [w, h]).astype(int)
    if x1 <= x0 or y1 <= y0:
        raise ValueError("the screen is outside the event camera's view")
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)


def flash_events(
    calib: Calibration,
    target: ScreenTarget,
    T_event_board: np.ndarray,
    switches_us: list[tuple[float, bool]],
    params: SensorParams,
    rng: np.random.Generator,
    *,
    fine_dt_us: float = 100.0,
    fine_us: float = 1000.0,
    coarse_dt_us: float = 1000.0,
    after_us: float = 3000.0,
) -> np.ndarray:
    """Events of the screen pixels around each switch ``(t_us, shown_after)`` at one pose.

    Each switch is simulated from 1 ms before to ``after_us`` after it: finely right after the
    switch (crossing times matter for the clock), coarsely while the photoreceptors settle.
    Between switches the scene is static and only noise fires, which ``background_events`` adds.
    """
    x0, y0, w, h = screen_region(calib, target, T_event_board)
    rays = region_rays(calib, x0, y0, w, h)
    shown, blank = target.render_pair(rays, (h, w), T_event_board)
    sensor = EventSensor(params, (h, w), (x0, y0), rng)
    out = []
    for t_switch, shown_after in switches_us:
        before, after = (blank, shown) if shown_after else (shown, blank)
        sensor.reset(before, t_switch - 1000.0, steady=True)
        out.append(sensor.step(before, 1000.0))
        t = 0.0
        while t < after_us:
            dt = fine_dt_us if t < fine_us else coarse_dt_us
            out.append(sensor.step(after, dt))
            t += dt
    return concat_events(out)


def camera_rays(camera: Camera) -> np.ndarray:
    """Normalised rays of every pixel centre of ``camera``, [h*w, 2]."""
    xs, ys = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    return camera.unproject(np.stack([xs.ravel(), ys.ravel()], axis=1))


def to_picture(irradiance: np.ndarray, white_lux: float, rng: np.random.Generator, *, noise: float = 2.0) -> np.ndarray:
    """Linear irradiance -> grey uint8 with an sRGB-like gamma and sensor noise."""
    linear = irradiance / np.float32(white_lux)
    grey = 255.0 * np.clip(linear, 0, 1) ** (1 / 2.2) + rng.normal(0.0, noise, linear.shape)
    return np.clip(np.round(grey), 0, 255).astype(np.uint8)


def shown_fraction(switch_times_us: np.ndarray, shown_after: np.ndarray, t0_us: np.ndarray, t1_us: np.ndarray, initial: bool = False) -> np.ndarray:
    """Share of each interval [t0, t1) during which the board was shown (square wave of switches)."""
    order = np.argsort(switch_times_us)
    times = np.asarray(switch_times_us, dtype=np.float64)[order]
    states = np.asarray(shown_after, dtype=bool)[order]
    t0 = np.asarray(t0_us, dtype=np.float64)
    t1 = np.asarray(t1_us, dtype=np.float64)
    edges = np.concatenate([[-np.inf], times, [np.inf]])
    level = np.concatenate([[initial], states]).astype(np.float64)
    total = np.zeros_like(t0)
    for k in range(level.size):  # a few dozen switches
        lo = np.maximum(t0, edges[k])
        hi = np.minimum(t1, edges[k + 1])
        total += level[k] * np.clip(hi - lo, 0.0, None)
    return total / np.maximum(t1 - t0, 1e-9)


@dataclass
class FlashCaptureSpec:
    """What a synthetic capture holds; defaults make a small one (seconds, a few poses).

    ``n_poses=1`` with several ``flashes_per_pose`` is a still capture, as the clock alignment wants.
    """

    seed: int = 0  # this capture's poses, switch times and noise
    device_seed: int = 0  # the glasses (true calibration, clocks, RGB camera pose): shared by a session's captures
    start_s: float = 0.0  # capture start within the session (both clocks advance by this)
    board: BoardSpec = field(default_factory=lambda: BoardSpec("charuco", 9, 6, 0.03, 0.022))
    n_poses: int = 6
    pose_s: float = 0.6  # glasses still for this long per pose
    flashes_per_pose: int = 1  # appear + disappear cycles per pose
    rgb_fps: float = 30.0
    rgb_exposure_us: float = 16000.0
    rgb_camera: Camera = field(default_factory=lambda: Intrinsics(512, 512, 700.0, 700.0, 255.5, 255.5, RECTIFIED))  # or Fisheye624Camera
    with_rgb: bool = True
    lux: float = 250.0
    distance_m: tuple[float, float] = (0.6, 0.7)
    tilt_scale: float = 1.6  # strong tilts separate focal length from distance


@dataclass
class FlashCapture:
    """A capture in memory (what ``write_flash_capture`` puts on disk) and its truth."""

    events: np.ndarray  # event clock
    board: BoardSpec
    rgb_times_us: np.ndarray  # device clock, exposure middles
    rgb_exposure_us: float
    rgb_frames: list[np.ndarray]
    rgb_camera: Camera
    truth: Calibration  # true event intrinsics, T_event_cpf and clock offset
    T_rgb_cpf: np.ndarray
    T_cpf_board: list[np.ndarray]  # per pose
    switches_event_us: np.ndarray  # true switch times on the event clock
    shown_after: np.ndarray

    def triggers(self) -> np.ndarray:
        """Edges on the external-trigger input (channel 0), as if the screen's sync output were wired
        to it: rising when the board appears, falling when it goes."""
        trig = np.zeros(self.switches_event_us.size, dtype=TRIGGER_DTYPE)
        trig["t"] = np.round(self.switches_event_us).astype(np.int64)
        trig["p"] = self.shown_after.astype(np.int16)
        return trig

    def nominal_calibration(self) -> Calibration:
        """What a user knows before calibrating: the RGB camera; nominal event-camera values."""
        w, h = SENSOR_WH
        return Calibration(
            width=w, height=h, fx=1400.0, fy=1400.0, cx=w / 2, cy=h / 2, distortion=(0.0, 0.0, 0.0, 0.0),
            T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=0,
            rgb_camera=rgb_camera_block(self.rgb_camera, self.T_rgb_cpf)
            if self.rgb_frames and isinstance(self.rgb_camera, Intrinsics) else None,
        )


def _rgb_pose(rng: np.random.Generator) -> np.ndarray:
    """The RGB camera a few cm to the right of the CPF, looking slightly down-outwards (Aria-like)."""
    T = np.eye(4)
    flip = np.diag([-1.0, -1.0, 1.0])
    T[:3, :3] = rotation_xyz(*np.radians(rng.normal([3.0, -9.0, 0.5], 0.5))) @ flip
    T[:3, 3] = [0.04 + rng.normal(0, 0.002), 0.006, 0.011]
    return T


def _poses(spec: FlashCaptureSpec, target: ScreenTarget, rng: np.random.Generator) -> list[np.ndarray]:
    """Board poses in the event camera frame that cover the image: centre, corners, tilted."""
    offsets = [(0.0, 0.0), (-0.14, -0.07), (0.14, -0.07), (-0.14, 0.07), (0.14, 0.07), (0.0, 0.0), (0.0, -0.08), (0.0, 0.08)]
    tilts = [(0, 0, 0), (15, -20, 5), (-15, -20, -5), (15, 20, 3), (-15, 20, -3), (-25, 0, 10), (20, 10, 0), (-20, -10, 0)]
    poses = []
    for k in range(spec.n_poses):
        tilt = np.array(tilts[k % len(tilts)], dtype=np.float64) * spec.tilt_scale + rng.normal(0, 2, 3)
        distance = float(rng.uniform(*spec.distance_m))
        off = np.array(offsets[k % len(offsets)]) * distance / 0.65
        poses.append(look_at_board(target, distance, tuple(tilt), tuple(off)))
    return poses


def unique_events(events: np.ndarray, width: int = SENSOR_WH[0], height: int = SENSOR_WH[1]) -> np.ndarray:
    """Time-sorted events, at most one per pixel and microsecond (as a sensor reports them)."""
    key = (events["t"].astype(np.int64) - int(events["t"].min(initial=0))) * (width * height) + (
        events["y"].astype(np.int64) * width + events["x"]
    )
    _, first = np.unique(key, return_index=True)
    return events[first]


def simulate_flash_capture(spec: FlashCaptureSpec | None = None) -> FlashCapture:
    """Simulate a capture: bursts of events at every switch, RGB frames on the device clock."""
    spec = spec if spec is not None else FlashCaptureSpec()
    device = np.random.default_rng([spec.device_seed, 11])  # the glasses: same for every capture of a session
    true_calib = random_calibration(device)
    # the session (all its captures) stays within one period of the sensor's 24-bit clock, so a RAW
    # file's own time base is the session's and one clock offset holds for every capture
    event_t0 = int(device.integers(0, (1 << 24) - SESSION_US))
    device_t0 = int(device.integers(5_000_000_000, 20_000_000_000))
    true_calib = replace(true_calib, gaze_to_event_time_offset_us=event_t0 - device_t0)
    T_rgb_cpf = _rgb_pose(device)
    start_us = round(spec.start_s * 1e6)
    if start_us + spec.n_poses * spec.pose_s * 1e6 > SESSION_US:
        raise ValueError(f"a capture must end within {SESSION_US / 1e6:.0f} s of the session start")
    event_t0 += start_us
    device_t0 += start_us
    rng = np.random.default_rng([spec.seed, 7])
    target = ScreenTarget(spec.board, white_lux=spec.lux)
    params = SensorParams(lux=spec.lux, c_on=0.3, c_off=0.3)
    poses_event = _poses(spec, target, rng)

    switches, states, events = [], [], []
    cycle_us = spec.pose_s * 1e6 / spec.flashes_per_pose
    for k, T_event_board in enumerate(poses_event):
        pose_switches = []
        for j in range(spec.flashes_per_pose):
            base = k * spec.pose_s * 1e6 + j * cycle_us
            on = base + rng.uniform(0.1, 0.3) * cycle_us + 0.37
            off = on + rng.uniform(0.35, 0.5) * cycle_us + 0.61
            pose_switches += [(on, True), (off, False)]
        events.append(flash_events(true_calib, target, T_event_board, pose_switches, params, rng))
        switches += [s for s, _ in pose_switches]
        states += [b for _, b in pose_switches]
    duration_us = int(spec.n_poses * spec.pose_s * 1e6)
    events.append(background_events(params, 0, duration_us, SENSOR_WH, None, rng))
    ev = unique_events(concat_events(events))
    ev = ev[(ev["t"] >= 0) & (ev["t"] < duration_us)]
    ev["t"] += event_t0

    switches_event = np.asarray(switches) + event_t0
    states_arr = np.asarray(states, dtype=bool)
    T_cpf_event = np.linalg.inv(true_calib.T_event_cpf)
    T_cpf_board = [T_cpf_event @ T for T in poses_event]
    times, frames = np.zeros(0), []
    if spec.with_rgb:
        times, frames = _rgb_frames(spec, target, T_rgb_cpf, T_cpf_board, switches_event - true_calib.gaze_to_event_time_offset_us, states_arr, device_t0, duration_us, rng)
    return FlashCapture(ev, spec.board, times, spec.rgb_exposure_us, frames, spec.rgb_camera, true_calib, T_rgb_cpf, T_cpf_board, switches_event, states_arr)


def write_flash_capture(out: str | Path, capture: FlashCapture) -> Path:
    """Write a capture folder: ``events.raw``, ``board.json``, ``rgb_frames.csv`` + PNG frames, and an
    input ``calibration.json`` with only what a user knows beforehand (see ``nominal_calibration``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_raw(out / "events.raw", capture.events, width=SENSOR_WH[0], height=SENSOR_WH[1], triggers=capture.triggers())
    save_board(out / "board.json", capture.board)
    if capture.rgb_frames:
        (out / "rgb_frames").mkdir(exist_ok=True)
        with open(out / RGB_FRAMES_NAME, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(["timestamp_us", "exposure_us", "file"])
            for t, picture in zip(capture.rgb_times_us, capture.rgb_frames):
                name = f"rgb_frames/{int(t)}.png"
                write_png(out / name, picture)
                writer.writerow([int(t), int(capture.rgb_exposure_us), name])
    save_calibration(out / "calibration.json", capture.nominal_calibration())
    if capture.rgb_frames and isinstance(capture.rgb_camera, Fisheye624Camera):
        # an Aria-style device calibration; the synthetic device frame is the CPF
        doc = {"CameraCalibrations": [{
            "Label": "camera-rgb",
            "Projection": {"Name": "FisheyeRadTanThinPrism", "Params": list(capture.rgb_camera.params)},
            "T_Device_Camera": aria_pose(np.linalg.inv(capture.T_rgb_cpf)),
            "ConfigData": {"ImageWidth": capture.rgb_camera.width, "ImageHeight": capture.rgb_camera.height},
        }]}
        (out / "device_calibration.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
        (out / "T_device_cpf.json").write_text(json.dumps(np.eye(4).tolist()), encoding="utf-8")
    return out


def aria_pose(T: np.ndarray) -> dict:
    """4x4 -> ``{Translation, UnitQuaternion: [w, [x, y, z]]}`` as in Aria calibration files."""
    rvec = cv2.Rodrigues(np.asarray(T[:3, :3], dtype=np.float64))[0].reshape(3)
    angle = float(np.linalg.norm(rvec))
    axis = rvec / angle if angle > 0 else np.zeros(3)
    w, xyz = math.cos(angle / 2), axis * math.sin(angle / 2)
    return {"Translation": [float(v) for v in T[:3, 3]], "UnitQuaternion": [w, [float(v) for v in xyz]]}


def rgb_camera_block(camera: Intrinsics, T_rgb_cpf: np.ndarray) -> dict:
    return {
        "width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
        "distortion": {"model": "none"}, "T_rgb_cpf": np.asarray(T_rgb_cpf).tolist(),
    }


def _rgb_frames(
    spec: FlashCaptureSpec, target: ScreenTarget, T_rgb_cpf: np.ndarray, T_cpf_board: list[np.ndarray],
    switches_device_us: np.ndarray, states: np.ndarray, device_t0: int, duration_us: int, rng: np.random.Generator,
) -> tuple[np.ndarray, list[np.ndarray]]:
    period = 1e6 / spec.rgb_fps
    mids = np.round(device_t0 + rng.uniform(0, period) + np.arange(int(duration_us / period)) * period)
    half = spec.rgb_exposure_us / 2
    mids = mids[mids + half < device_t0 + duration_us]
    fractions = shown_fraction(switches_device_us, states, mids - half, mids + half)
    rays = camera_rays(spec.rgb_camera)
    shape = (spec.rgb_camera.height, spec.rgb_camera.width)
    pairs = [target.render_pair(rays, shape, T_rgb_cpf @ T) for T in T_cpf_board]
    frames = []
    for mid, frac in zip(mids, fractions):
        k = min(int((mid - device_t0) // (spec.pose_s * 1e6)), len(T_cpf_board) - 1)
        frames.append(to_picture(ScreenTarget.blend(*pairs[k], float(frac)), target.white_lux, rng))
    return mids.astype(np.int64), frames


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    cos = (np.trace(R_a.T @ R_b) - 1) / 2
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


@dataclass
class GazeFlowScene:
    """Events and gaze of a reader whose head moves, for the clock refinement (no page rendering).

    The page image shifts by ``shift(t)`` (head motion); page features fire events at a rate
    proportional to the image speed; the gaze holds on a word during a fixation (so its pixel moves
    with the page) and jumps between words in saccades. Gaze rows are on the device clock.
    """

    events: np.ndarray
    gaze_t_device_us: np.ndarray
    gaze_pixels: np.ndarray
    offset_us: int  # true t_event - t_device


def simulate_gaze_flow(seed: int = 0, seconds: float = 6.0, *, gaze_hz: float = 60.0, events_per_px: float = 400.0) -> GazeFlowScene:
    rng = np.random.default_rng([seed, 13])
    dt_us = 500
    t = np.arange(0, int(seconds * 1e6), dt_us, dtype=np.int64)
    ts = t * 1e-6
    shift = np.zeros((t.size, 2))
    for _ in range(6):  # head motion: a few smooth oscillations per axis
        f = rng.uniform(0.3, 2.5)
        amp = rng.uniform(3.0, 14.0, 2)
        phase = rng.uniform(0, 2 * np.pi, 2)
        shift += amp * np.sin(2 * np.pi * f * ts[:, None] + phase)
    velocity = np.gradient(shift, ts, axis=0)
    speed = np.linalg.norm(velocity[:-1] + velocity[1:], axis=1) / 2  # px/s over each step
    t, shift = t[:-1], shift[:-1]
    features = np.c_[rng.uniform(300, 900, 4000), rng.uniform(250, 450, 4000)]
    n_per_step = rng.poisson(speed * events_per_px * dt_us * 1e-6)
    step = np.repeat(np.arange(t.size), n_per_step)
    feat = rng.integers(0, len(features), step.size)
    pos = features[feat] + shift[step] + rng.normal(0, 0.7, (step.size, 2))
    noise_n = int(seconds * 50_000)
    event_t0 = int(rng.integers(0, 1 << 24))
    x = np.concatenate([pos[:, 0], rng.uniform(0, 1280, noise_n)])
    y = np.concatenate([pos[:, 1], rng.uniform(0, 720, noise_n)])
    tt = np.concatenate([t[step] + rng.integers(0, dt_us, step.size), rng.integers(0, t[-1], noise_n)])
    ev = np.zeros(x.size, dtype=EVENT_CD_DTYPE)
    ev["x"] = np.clip(np.round(x), 0, 1279)
    ev["y"] = np.clip(np.round(y), 0, 719)
    ev["t"] = tt + event_t0
    ev["p"] = rng.integers(0, 2, x.size)
    ev = ev[np.argsort(ev["t"], kind="stable")]
    # reading: fixations of 150-350 ms on successive words, 30 ms saccades
    device_t0 = int(rng.integers(5_000_000_000, 20_000_000_000))
    rows = np.cumsum(rng.uniform(0.8, 1.2, int(seconds * gaze_hz * 1.2)) * 1e6 / gaze_hz)
    rows = rows[rows < seconds * 1e6 - 1]
    fix_end = np.cumsum(rng.uniform(150e3, 350e3, 200))
    word = np.searchsorted(fix_end, rows)
    target = np.c_[350 + (word % 12) * 45.0, 300 + (word // 12 % 4) * 30.0]
    since = rows - np.concatenate([[0.0], fix_end])[word]
    prev = np.c_[350 + ((word - 1) % 12) * 45.0, 300 + ((word - 1) // 12 % 4) * 30.0]
    w = np.clip(since / 30e3, 0, 1)[:, None]
    page_point = prev + w * (target - prev)
    head = np.c_[np.interp(rows, t, shift[:, 0]), np.interp(rows, t, shift[:, 1])]
    gaze_px = page_point + head + rng.normal(0, 0.5, page_point.shape)
    offset = event_t0 - device_t0
    return GazeFlowScene(ev, (device_t0 + rows).astype(np.int64), gaze_px, offset)


def evaluate_session(*, device_seed: int = 0, n_poses: int = 8, flashes_per_pose: int = 2, seed: int = 1) -> list[dict]:
    """Calibrate a synthetic session (posed capture, still capture, reading-like gaze scene) with the
    library functions and return rows of recovered-vs-true values for docs/calibration.md."""
    from darkread.edge.calibrate.capture import paired_views
    from darkread.edge.calibrate.clock import (
        RgbFrames,
        fit_offset,
        refine_offset,
        switches_from_bursts,
        switches_from_triggers,
    )
    from darkread.edge.calibrate.event_image import find_bursts
    from darkread.edge.calibrate.extrinsics import extrinsics_from_views
    from darkread.edge.calibrate.intrinsics import calibrate_intrinsics, detect_views

    def frames(c: FlashCapture, side: int | None) -> RgbFrames:
        images = c.rgb_frames if side is None else [cv2.resize(im, (side, side), interpolation=cv2.INTER_AREA) for im in c.rgb_frames]
        return RgbFrames(c.rgb_times_us, np.full(len(images), c.rgb_exposure_us), images)

    still = simulate_flash_capture(FlashCaptureSpec(seed=seed + 1, device_seed=device_seed, start_s=0.0, n_poses=1, pose_s=2.0,
                                                    flashes_per_pose=6, distance_m=(1.0, 1.1)))
    posed = simulate_flash_capture(FlashCaptureSpec(seed=seed, device_seed=device_seed, start_s=3.0, n_poses=n_poses,
                                                    pose_s=0.5 * flashes_per_pose, flashes_per_pose=flashes_per_pose))
    truth = posed.truth
    rows: list[dict] = []
    views = detect_views(posed.events, posed.board, *SENSOR_WH)
    intr = calibrate_intrinsics([v.detection for v in views if v.detection is not None], *SENSOR_WH)
    for name in ("fx", "fy", "cx", "cy"):
        rows.append({"quantity": f"{name} (px)", "true": getattr(truth, name), "recovered": getattr(intr, name),
                     "sigma": intr.std[name]})
    for i, name in enumerate(("k1", "k2")):
        rows.append({"quantity": name, "true": truth.distortion[i], "recovered": intr.distortion[i], "sigma": intr.std[name]})
    rows.append({"quantity": "reprojection RMS (px)", "true": 0.0, "recovered": intr.rms_px, "sigma": None})
    estimate = replace(truth, fx=intr.fx, fy=intr.fy, cx=intr.cx, cy=intr.cy, distortion=intr.distortion)
    xs, ys = np.meshgrid(np.linspace(-0.36, 0.36, 25), np.linspace(-0.2, 0.2, 15))
    pts = np.c_[xs.ravel(), ys.ravel(), np.ones(xs.size)]
    field_err = np.linalg.norm(estimate.project(pts) - truth.project(pts), axis=1)
    rows.append({"quantity": "projection vs truth, central field, mean / max (px)", "true": 0.0,
                 "recovered": f"{field_err.mean():.2f} / {field_err.max():.2f}", "sigma": None})

    sw, shown = switches_from_bursts(find_bursts(still.events))
    clock = fit_offset(sw, shown, frames(still, 128))
    true_offset = truth.gaze_to_event_time_offset_us
    rows.append({"quantity": "clock offset error, burst onsets vs RGB (us)", "true": 0.0,
                 "recovered": clock.offset_us - true_offset, "sigma": clock.uncertainty_us})
    sw, shown = switches_from_triggers(still.triggers())
    clock_t = fit_offset(sw, shown, frames(still, 128), source="trigger")
    rows.append({"quantity": "clock offset error, trigger input vs RGB (us)", "true": 0.0,
                 "recovered": clock_t.offset_us - true_offset, "sigma": clock_t.uncertainty_us})

    pairs = paired_views(posed.events, find_bursts(posed.events), frames(posed, None), clock.offset_us, posed.board, *SENSOR_WH)
    event_camera = Intrinsics(SENSOR_WH[0], SENSOR_WH[1], intr.fx, intr.fy, intr.cx, intr.cy, intr.distortion)
    ext = extrinsics_from_views(pairs, event_camera, posed.rgb_camera, posed.T_rgb_cpf)
    rows.append({"quantity": f"T_event_cpf rotation error (deg), {ext.n_views} views", "true": 0.0,
                 "recovered": rotation_angle_deg(ext.T_event_cpf[:3, :3], truth.T_event_cpf[:3, :3]), "sigma": None})
    rows.append({"quantity": "T_event_cpf translation error (mm)", "true": 0.0,
                 "recovered": 1000 * float(np.linalg.norm(ext.T_event_cpf[:3, 3] - truth.T_event_cpf[:3, 3])), "sigma": None})
    from darkread.edge.calibrate.event_image import latency_image
    from darkread.edge.calibrate.extrinsics import page_homography
    from darkread.edge.calibrate.markers import detect_board

    page = simulate_page_capture(seed=seed, device_seed=device_seed)
    lamp = find_bursts(page.events)[0]
    event_det = detect_board(latency_image(page.events, *SENSOR_WH, lamp.onset_us - 200), page.markers, min_corners=4)
    rgb_det = detect_board(page.rgb_frame, page.markers, min_corners=4)
    if event_det is not None and rgb_det is not None:
        hom = page_homography(event_det, rgb_det)
        xs, ys = np.meshgrid(np.linspace(0.0, 0.215, 8), np.linspace(0.0, 0.215, 8))
        pts = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
        T_event, T_rgb = truth.T_event_cpf @ page.T_cpf_page, page.T_rgb_cpf @ page.T_cpf_page
        err = np.linalg.norm(hom.map(page.rgb_camera.project(pts @ T_rgb[:3, :3].T + T_rgb[:3, 3]))
                             - page.truth.project(pts @ T_event[:3, :3].T + T_event[:3, 3]), axis=1)
        rows.append({"quantity": "page homography (fallback): RGB->event error on the page, mean / max (px)", "true": 0.0,
                     "recovered": f"{err.mean():.2f} / {err.max():.2f}", "sigma": None})
    errors = []
    for s in range(5):
        scene = simulate_gaze_flow(s)
        ref = refine_offset(scene.events["t"], scene.gaze_t_device_us, scene.gaze_pixels, scene.offset_us + 15_000)
        errors.append(ref.offset_us - scene.offset_us)
    rows.append({"quantity": "clock refinement error from a 15 ms error, 5 gaze-flow scenes (us)", "true": 0.0,
                 "recovered": " / ".join(f"{e:+.0f}" for e in errors), "sigma": None})
    return rows


# -- a printed page with static markers around the text, lit by a lamp switched on --------------


@dataclass
class PageCapture:
    """Static ArUco markers printed around text, seen by the event camera when a lamp is switched on
    and by one RGB frame of the lit page; for the flat-page homography fallback."""

    events: np.ndarray
    markers: BoardSpec  # a 2 x 2 grid: one marker in each corner around the text
    rgb_frame: np.ndarray
    rgb_camera: Intrinsics
    truth: Calibration
    T_rgb_cpf: np.ndarray
    T_cpf_page: np.ndarray
    px_per_m: float
    margin_m: float


def page_texture(markers: BoardSpec, lines: list[str], px_per_m: float, margin_m: float) -> np.ndarray:
    """Paper reflectance: the four corner markers and the text between them (DejaVu Sans)."""
    from darkread.models.synth.fonts import face_by_name
    from darkread.models.synth.page import render_page

    board = markers.image(px_per_m).astype(np.float32) / 255.0
    m = round(margin_m * px_per_m)
    ink = 1.0 - np.pad(board, m, constant_values=1.0)
    gap = round((markers.square_m - markers.marker_m) * px_per_m)
    page = render_page(lines, face_by_name("DejaVu Sans"), xheight_tex=gap / (len(lines) * 3.0), texel_m=1 / px_per_m,
                       margin_xheights=2.0)
    text = page.coverage[: gap - 4, : gap - 4]
    top = m + round(markers.marker_m * px_per_m) + 2
    ink[top : top + text.shape[0], top : top + text.shape[1]] = np.maximum(ink[top : top + text.shape[0], top : top + text.shape[1]], text)
    return (0.85 * (1.0 - 0.88 * np.clip(ink, 0, 1))).astype(np.float32)


def simulate_page_capture(seed: int = 0, device_seed: int = 0, *, lux: float = 30.0, distance_m: float = 0.7) -> PageCapture:
    """The lamp goes from 0.3 lux to ``lux``: paper gains more log-intensity than ink (the sensor's dark
    current), so paper fires more events than the printed markers and text."""
    device = np.random.default_rng([device_seed, 11])
    truth = random_calibration(device)
    device.integers(0, 1 << 24)  # keep the device stream aligned with simulate_flash_capture
    device.integers(5_000_000_000, 20_000_000_000)
    T_rgb_cpf = _rgb_pose(device)
    rng = np.random.default_rng([seed, 17])
    markers = BoardSpec("grid", 2, 2, square_m=0.17, marker_m=0.045)
    px_per_m, margin_m = 2500.0, 0.01
    texture = cv2.GaussianBlur(page_texture(markers, ["calibrate the", "glasses on a", "printed page"], px_per_m, margin_m), (0, 0), 0.6)
    size = markers.size_m[0] + 2 * margin_m
    T_event_page = look_at_board(ScreenTarget(markers, margin_m=margin_m), distance_m, tuple(rng.normal(0, 8, 3)))
    params = SensorParams(lux=lux, c_on=0.25, c_off=0.25)
    corners = np.array([[-margin_m, -margin_m, 0], [size - margin_m, -margin_m, 0], [size - margin_m, size - margin_m, 0], [-margin_m, size - margin_m, 0]])
    uv = truth.project(corners @ T_event_page[:3, :3].T + T_event_page[:3, 3])
    x0, y0 = np.maximum(np.floor(uv.min(axis=0)) - 8, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(uv.max(axis=0)) + 9, SENSOR_WH).astype(int)
    rays = region_rays(truth, int(x0), int(y0), int(x1 - x0), int(y1 - y0))
    shape = (int(y1 - y0), int(x1 - x0))
    value, outside = sample_plane(texture, px_per_m, margin_m, rays, shape, T_event_page)
    reflect = np.where(outside, np.float32(0.15), value)
    sensor = EventSensor(params, shape, (int(x0), int(y0)), rng)
    off, on = reflect * np.float32(0.3), reflect * np.float32(lux)
    sensor.reset(off, 0.0, steady=True)
    parts = [sensor.step(off, 1000.0)]
    for _ in range(30):  # 15 ms after the switch: dim pixels settle slowly
        parts.append(sensor.step(on, 500.0))
    parts.append(background_events(params, 0, 40_000, SENSOR_WH, (int(x0), int(y0), shape[1], shape[0]), rng))
    events = unique_events(concat_events(parts))
    events = events[(events["t"] >= 0) & (events["t"] < 40_000)]
    events["t"] += 1_000_000
    rgb_camera = Intrinsics(512, 512, 700.0, 700.0, 255.5, 255.5, RECTIFIED)
    T_cpf_page = np.linalg.inv(truth.T_event_cpf) @ T_event_page
    rgb_value, rgb_outside = sample_plane(texture, px_per_m, margin_m, camera_rays(rgb_camera), (512, 512), T_rgb_cpf @ T_cpf_page)
    rgb = to_picture(np.where(rgb_outside, np.float32(0.15), rgb_value) * np.float32(lux), lux * 0.9, rng)
    return PageCapture(events, markers, rgb, rgb_camera, truth, T_rgb_cpf, T_cpf_page, px_per_m, margin_m)


def write_page_capture(out: str | Path, page: PageCapture) -> Path:
    """A capture folder for ``darkread calibrate extrinsics --homography-only``: the lamp burst in
    ``events.raw``, the page markers in ``board.json``, one RGB frame 0.2 s after the lamp (device
    clock = event clock here, offset 0)."""
    out = Path(out)
    (out / "rgb_frames").mkdir(parents=True, exist_ok=True)
    write_raw(out / "events.raw", page.events, width=SENSOR_WH[0], height=SENSOR_WH[1])
    save_board(out / "board.json", page.markers)
    write_png(out / "rgb_frames" / "1200000.png", page.rgb_frame)
    (out / RGB_FRAMES_NAME).write_text("timestamp_us,exposure_us,file\n1200000,16000,rgb_frames/1200000.png\n", encoding="utf-8")
    nominal = replace(page.truth, gaze_to_event_time_offset_us=0, rgb_camera=rgb_camera_block(page.rgb_camera, page.T_rgb_cpf))
    save_calibration(out / "calibration.json", nominal)
    return out


if __name__ == "__main__":
    for row in evaluate_session():
        sigma = "" if row["sigma"] is None else f"{row['sigma']:.4g}"
        rec = row["recovered"] if isinstance(row["recovered"], str) else f"{row['recovered']:.5g}"
        print(f"| {row['quantity']} | {row['true']:.5g} | {rec} | {sigma} |")
