"""Whole synthetic reading sessions written in the recording format.

The region the fovea can reach (every window around the tracker's gaze estimates, plus a margin)
is simulated pixel by pixel at >= 2 kHz; the rest of the sensor receives noise events at the same
per-pixel rates (shot, leak, hot pixels), which keeps generation fast. ``RecordingSpec.full_view``
simulates the whole sensor instead, with the paper's edge and a textured desk around it, as glasses
see a page at reading distance (about ten times slower: the stream an on-sensor ROI is measured
on). Event times are absolute sensor time starting anywhere in the 24-bit range; gaze rows are on the device clock, related to
the event clock by ``calibration.json``'s offset (written with a few ms of alignment error).
"""

from __future__ import annotations

import json
import logging
import math
import time
import uuid
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from darkread.edge.events import EVENT_CD_DTYPE
from darkread.edge.fovea import FoveaConfig
from darkread.edge.io.calibration import save_calibration
from darkread.edge.io.gaze_csv import write_gaze_csv
from darkread.edge.io.imu_csv import IMU_NAME
from darkread.edge.io.raw import write_raw
from darkread.edge.sources.evk4.bias_profiles import FACTORY, profile_offsets
from darkread.models.synth.camera import SENSOR_WH
from darkread.models.synth.gaze import points_from_angles, row_times_us, tracker_rows
from darkread.models.synth.human_scanpath import SHIPPED, HumanScanpath
from darkread.models.synth.imu import write_imu
from darkread.models.synth.marker_page import save_layout
from darkread.models.synth.scene import Region
from darkread.models.synth.sensor import DEFAULT_F_NUMBER, EventSensor, background_events, concat_events
from darkread.models.synth.session import Session, SessionSpec, choose_dt_us, make_session
from darkread.models.synth.text import CORPUS_SOURCE

log = logging.getLogger(__name__)

REGION_MARGIN_PX = 16
WRAP_US = 1 << 24
READ_ONCE_TAIL_S = 0.3  # kept after the last line was read, as a reader pauses before looking away


@dataclass(frozen=True)
class RecordingSpec:
    lux: float = 100.0
    motion: str = "normal"
    kind: str = "paragraph"
    seconds: float = 10.0
    seed: int = 0
    font: str | None = None
    xheight_px: float | None = None
    n_lines: int | None = None
    line_chars: int | None = None
    description: str = "synthetic reading session"
    split: str = "train"  # "val": texts never used for training (evaluation)
    read_once: bool = False  # stop once the page was read (``seconds`` is then the upper bound)
    scanpath: str = "model"  # "human": a real reader's fixations replayed (models/synth/human_scanpath.py)
    scanpath_file: str | None = None
    regime: str = "standard"  # "shifted": a sensor and a font training never saw
    markers: bool = False  # the text printed with ArUco markers around it (page.layout.json)
    simulator: str = "darkread"  # the name of what turned the scene into events (``write_recording``'s ``simulator``)
    f_number: float = DEFAULT_F_NUMBER  # the lens; what share of the page's light reaches the chip (regime "grounded")
    bias_profile: str = FACTORY  # the IMX636 biases it is made with (edge/sources/evk4/bias_profiles.py)
    sensor_profile: str | None = None  # a measured sensor profile the grounded sensor is drawn from
    k_hz_per_chip_lux: float | None = None  # grounded: the photoreceptor's K fixed (None: drawn over its band)
    standard_laws: tuple[str, ...] = ()  # grounded: laws put back to the standard model's (sensor.STANDARD_LAWS)
    motion_regime: str = "standard"  # the head motion's draws (models/synth/motion.py MOTION_REGIMES)
    full_view: bool = False  # simulate every pixel of the sensor (the page, its edge, a desk) instead of the reachable region

    def __post_init__(self) -> None:
        # a spec read back from JSON (spec.json, suite.json) holds a list here: the same spec, so equal
        object.__setattr__(self, "standard_laws", tuple(self.standard_laws))


LAYOUT_NAME = "page.layout.json"
POSE_TRUTH_NAME = "pose_truth.npz"
PAGE_INK_NAME = "page_ink.npz"  # a plain page's ink (a marker page's is re-created from its layout)
POSE_TRUTH_STEP_US = 1000


def session_spec(spec: RecordingSpec) -> SessionSpec:
    """The session a recording spec simulates (also how the RGB baseline re-creates its scene)."""
    return SessionSpec(
        split=spec.split, lux=spec.lux, motion=spec.motion, kind=spec.kind, font=spec.font,
        xheight_px=spec.xheight_px, n_lines=spec.n_lines, line_chars=spec.line_chars, duration_s=spec.seconds,
        scanpath=spec.scanpath, scanpath_file=spec.scanpath_file, regime=spec.regime, markers=spec.markers,
        f_number=spec.f_number, bias_profile=spec.bias_profile, sensor_profile=spec.sensor_profile,
        k_hz_per_chip_lux=spec.k_hz_per_chip_lux, standard_laws=spec.standard_laws, motion_regime=spec.motion_regime, full_view=spec.full_view,
    )


def recording_seconds(spec: RecordingSpec, session: Session) -> float:
    """How long the recording lasts: ``seconds``, or less when it ends after one reading of the page."""
    if not spec.read_once:
        return float(spec.seconds)
    return float(min(spec.seconds, session.scanpath.first_pass_end_s() + READ_ONCE_TAIL_S))


def _cpf_points(session: Session, tex_xy: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """CPF points (m) of texels ``tex_xy`` [N, 2] at times ``t_s`` [N]."""
    T = session.calib.T_event_cpf
    rot, trans = T[:3, :3], T[:3, 3]
    out = np.empty((len(t_s), 3))
    for i, (xy, t) in enumerate(zip(tex_xy, t_s)):  # one row per eye-tracking frame (~60 per second)
        p_cam = session.scene.points_camera(xy[None, :], float(t))[0]
        out[i] = rot.T @ (p_cam - trans)
    return out


def gaze_rows(session: Session, device_t0_us: int, seconds: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The tracker's rows: device times, per-eye yaws, pitch, depth, and the blink flag."""
    tr = session.tracker
    t_rows = row_times_us(device_t0_us, seconds, tr.rate_hz, tr.missing_p, rng)
    t_rows = t_rows[t_rows < device_t0_us + int(seconds * 1e6)]
    eye_t = (t_rows - device_t0_us) * 1e-6 - tr.latency_us * 1e-6
    tex = session.scanpath.position(np.maximum(eye_t, 0.0))
    true_cpf = _cpf_points(session, tex, np.maximum(eye_t, 0.0))
    blink = session.scanpath.in_blink(eye_t)
    left, right, pitch, depth = tracker_rows(true_cpf, t_rows, blink, tr, rng)
    return {"t_us": t_rows, "left": left, "right": right, "pitch": pitch, "depth": depth, "blink": blink}


def gaze_pixels(session: Session, rows: dict[str, np.ndarray]) -> np.ndarray:
    """Where the edge will centre its window for each row (format's worked example)."""
    tc = (np.tan(rows["left"]) + np.tan(rows["right"])) / 2
    p_cpf = points_from_angles(np.arctan(tc), rows["pitch"], rows["depth"])
    return session.calib.project(session.calib.cpf_to_event(p_cpf))


FOVEA = FoveaConfig()


def reachable_region(uv: np.ndarray, fovea: FoveaConfig = FOVEA, margin: int = REGION_MARGIN_PX) -> tuple[int, int, int, int]:
    """(x0, y0, w, h): every fovea window around ``uv`` plus a margin, clipped to the sensor."""
    ok = np.all(np.isfinite(uv), axis=1)
    if not ok.any():
        raise ValueError("no finite gaze pixel: cannot place the simulated region")
    lo = np.percentile(uv[ok], 1, axis=0)
    hi = np.percentile(uv[ok], 99, axis=0)
    half = np.array([fovea.width / 2 + margin, fovea.height / 2 + margin])
    x0, y0 = np.maximum(np.floor(lo - half), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(hi + half), np.array(SENSOR_WH)).astype(int)
    return int(x0), int(y0), int(max(x1 - x0, 1)), int(max(y1 - y0, 1))


def page_region(session: Session, seconds: float, margin: int = REGION_MARGIN_PX) -> tuple[int, int, int, int]:
    """(x0, y0, w, h): the sensor pixels the marker page covers at any time of the recording."""
    page = session.marker_page
    assert page is not None
    _, corners = page.marker_points()
    pts = corners.reshape(-1, 2)
    hom = page_to_camera(session, np.arange(0.0, seconds + 0.025, 0.025))
    uv = np.concatenate([session.calib.project(np.c_[pts, np.ones(len(pts))] @ h.T) for h in hom])
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    x0, y0 = np.maximum(np.floor(uv.min(axis=0)) - margin, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(uv.max(axis=0)) + margin, np.array(SENSOR_WH)).astype(int)
    return int(x0), int(y0), int(max(x1 - x0, 1)), int(max(y1 - y0, 1))


def union_region(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    x0, y0 = min(a[0], b[0]), min(a[1], b[1])
    x1, y1 = max(a[0] + a[2], b[0] + b[2]), max(a[1] + a[3], b[1] + b[3])
    return x0, y0, x1 - x0, y1 - y0


def page_to_camera(session: Session, t_s: np.ndarray) -> np.ndarray:
    """[n, 3, 3]: page millimetres (x, y, 1) -> camera-frame point (m) at each time (the true pose)."""
    s = session.texels_per_mm
    mm_to_texel = np.array([[s, 0.0, -0.5], [0.0, s, -0.5], [0.0, 0.0, 1.0]])
    return np.stack([session.scene.texel_to_camera(float(t)) @ mm_to_texel for t in np.atleast_1d(t_s)])


def write_pose_truth(path: Path, session: Session, seconds: float, event_t0: int) -> None:
    """The simulator's page-to-camera pose every millisecond on the event clock (for scoring only)."""
    t_s = np.arange(0, int(seconds * 1e6) + 1, POSE_TRUTH_STEP_US) * 1e-6
    np.savez_compressed(
        path, t_us=(event_t0 + np.round(t_s * 1e6)).astype(np.int64), H_mm_to_camera=page_to_camera(session, t_s),
        note=np.array("page mm (x, y, 1) -> camera-frame point in metres; project with calibration.json's intrinsics"),
    )


def write_page_ink(path: Path, session: Session) -> None:
    """A plain page's ink raster, the simulator's own texture, in ``pose_truth.npz``'s millimetre frame.

    With the pose truth it gives every window its true ink (how ``train compare`` scores plain
    pages); a marker page does not need it, its layout re-creates the page.
    """
    np.savez_compressed(
        path, ink=session.page.coverage.astype(np.float32), px_per_mm=np.float64(session.texels_per_mm),
        note=np.array("ink coverage 0..1; pixel (i, j) covers x in [j, j + 1) / px_per_mm, y in [i, i + 1) / px_per_mm"),
    )


def read_truth(recording: str | Path, name: str, keys: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """The arrays ``keys`` of the truth file ``name`` beside a synthetic recording (None when there is
    none); a damaged one is a ValueError that says which file and how to make it again."""
    path = Path(recording) / name
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh, np.load(fh) as data:  # (np.load(path) leaks its file when the zip is damaged)
            return {key: np.asarray(data[key]) for key in keys}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a readable simulator truth file ({type(exc).__name__}: {exc}); "
                         "make the recording again with `darkread synth recording`") from exc


@dataclass
class PoseTruth:
    """The simulator's page pose (page mm -> camera point) per millisecond, for scoring only."""

    t_us: np.ndarray
    H: np.ndarray

    def at(self, t_us: float) -> np.ndarray:
        k = int(np.clip(np.searchsorted(self.t_us, t_us), 1, len(self.t_us) - 1))
        t0, t1 = self.t_us[k - 1], self.t_us[k]
        w = float(np.clip((t_us - t0) / max(t1 - t0, 1), 0.0, 1.0))
        return (1 - w) * self.H[k - 1] + w * self.H[k]


def load_pose_truth(recording: str | Path) -> PoseTruth | None:
    """The page's pose per millisecond a synthetic recording carries (None for a real one)."""
    data = read_truth(recording, POSE_TRUTH_NAME, ("t_us", "H_mm_to_camera"))
    return None if data is None else PoseTruth(data["t_us"].astype(np.float64), data["H_mm_to_camera"].astype(np.float64))


def load_page_ink(recording: str | Path) -> tuple[np.ndarray, float] | None:
    """(ink coverage, px_per_mm) of a plain synthetic page, or None when the recording has none."""
    data = read_truth(recording, PAGE_INK_NAME, ("ink", "px_per_mm"))
    return None if data is None else (data["ink"].astype(np.float32), float(data["px_per_mm"]))


def simulate_region(
    session: Session, region: Region, seconds: float, rng: np.random.Generator, *, progress: bool = False
) -> np.ndarray:
    """All events of ``region`` over [0, seconds) s; times in µs from the session start."""
    scene, params = session.scene, session.sensor
    dt_us = choose_dt_us(scene)
    sensor = EventSensor(params, (region.height, region.width), (region.x0, region.y0), rng)
    warm_steps, warm_dt_us = 15, 2000.0
    t = -warm_steps * warm_dt_us * 1e-6
    sensor.reset(scene.irradiance(region, t), t * 1e6)
    for _ in range(warm_steps):
        t += warm_dt_us * 1e-6
        sensor.settle(scene.irradiance(region, t), warm_dt_us)
    sensor.rebase()
    sensor.t = 0.0
    n_steps = int(math.ceil(seconds * 1e6 / dt_us))
    end_us = int(seconds * 1e6)
    chunks = []
    from tqdm import tqdm

    for k in tqdm(range(n_steps), disable=not progress, unit="step", desc="simulating", leave=False):
        t_s = (k + 1) * dt_us * 1e-6
        ev = sensor.step(scene.irradiance(region, t_s), dt_us)
        if ev.size and ev["t"][-1] >= end_us:  # (a step's events are time-sorted; only the last steps reach the end)
            ev = ev[ev["t"] < end_us]
        if ev.size:
            chunks.append(ev)
    return concat_events(chunks)  # (the events once more, not twice: models/synth/STATUS.md, "Memory")


def _clock_origins(rng: np.random.Generator) -> tuple[int, int]:
    """The event clock's and the device clock's times at the recording's start (the first draws of
    a recording's clock generator)."""
    return int(rng.integers(0, WRAP_US)), int(rng.integers(5_000_000_000, 20_000_000_000))


def _write_gyroscope(out: Path, spec: RecordingSpec, session: Session, seconds: float, device_t0: int) -> None:
    """``closed_loop_trajectory.csv``, from its own generator: the rest of the recording comes out as without it."""
    write_imu(out / IMU_NAME, session.scene, seconds, device_t0, np.random.default_rng([spec.seed, 4]))


def add_gyroscope(recording_dir: str | Path, spec: RecordingSpec) -> Path:
    """Give a recording ``write_recording(spec)`` made before recordings carried a gyroscope the
    ``closed_loop_trajectory.csv`` it would carry now (byte for byte); its other files stay as they are."""
    out = Path(recording_dir)
    session = make_session(session_spec(spec), spec.seed)
    _, device_t0 = _clock_origins(np.random.default_rng([spec.seed, 2]))
    _write_gyroscope(out, spec, session, recording_seconds(spec, session), device_t0)
    return out / IMU_NAME


class Simulator(Protocol):
    """What turns a session's scene into events: (events of the simulated region, noise events of
    the rest of the sensor, the sensor for ``meta.json``); times in us from the session start."""

    def __call__(self, spec: RecordingSpec, session: Session, region: Region, seconds: float,
                 rng: np.random.Generator, *, progress: bool = False) -> tuple[np.ndarray, np.ndarray, dict]: ...


def simulate_events(
    spec: RecordingSpec, session: Session, region: Region, seconds: float, rng: np.random.Generator, *,
    progress: bool = False,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Our sensor model (``sensor.py``): the ``Simulator`` every recording uses unless told otherwise."""
    x0, y0, w, h = region.x0, region.y0, region.width, region.height
    signal = simulate_region(session, region, seconds, rng, progress=progress)
    background = background_events(session.sensor, 0, int(seconds * 1e6), SENSOR_WH, (x0, y0, w, h), rng)
    return signal, background, session.sensor.to_dict()


def drop_same_time_duplicates(events: np.ndarray, width: int = SENSOR_WH[0]) -> np.ndarray:
    """Time-sorted events with at most one event per pixel and microsecond (as a sensor reports);
    of events at the same pixel and microsecond the first is kept."""
    pix = events["y"].astype(np.int64) * width + events["x"]
    order = np.lexsort((pix, events["t"]))
    ev = events[order]
    p = pix[order]
    keep = np.ones(ev.size, dtype=bool)
    keep[1:] = (ev["t"][1:] != ev["t"][:-1]) | (p[1:] != p[:-1])
    return ev[keep]


def merged_events(parts: list[np.ndarray], width: int = SENSOR_WH[0], events_per_window: int = 1 << 20) -> np.ndarray:
    """``drop_same_time_duplicates(concat_events(parts))``, a stretch of time at a time when every part
    is time-sorted (a simulator's signal and noise are): the sort held every event several times
    over (models/synth/STATUS.md, "Memory").
    Events of one microsecond always fall in one stretch, in the parts' order, so the result is
    the same array."""
    total = sum(p.size for p in parts)
    if total <= events_per_window or not all(p.size < 2 or bool(np.all(p["t"][1:] >= p["t"][:-1])) for p in parts):
        return drop_same_time_duplicates(concat_events(parts), width)
    step = max(1, events_per_window // max(1, len(parts)))
    bounds = np.unique(np.concatenate([p["t"][::step] for p in parts if p.size]))[1:]  # each stretch starts at one
    out = np.empty(total, dtype=EVENT_CD_DTYPE)  # (filled in place: a list of stretches joined would be a third copy)
    kept = 0
    starts = [0] * len(parts)
    for end_t in [*bounds.tolist(), None]:
        ends = [p.size if end_t is None else int(np.searchsorted(p["t"], end_t, side="left")) for p in parts]
        window = concat_events([p[a:b] for p, a, b in zip(parts, starts, ends, strict=True)])
        if window.size:
            merged = drop_same_time_duplicates(window, width)
            out[kept : kept + merged.size] = merged
            kept += merged.size
        starts = ends
    return out[:kept]


def write_recording(out: str | Path, spec: RecordingSpec, *, progress: bool = True,
                    simulator: Simulator = simulate_events) -> dict:
    """Write a recording folder (events.raw, general_eye_gaze.csv, calibration.json, text.txt, meta.json,
    closed_loop_trajectory.csv: the head's rotation as a MEMS gyroscope reports it, ``synth.imu``).

    ``simulator`` turns the scene into events (our sensor model unless the caller brings another one:
    ``spec.simulator`` names it in ``meta.json``).

    Beside them, for scoring only, the simulator's truth: ``pose_truth.npz`` (page pose per ms) and
    the page's ink (``page.layout.json`` for a marker page, ``page_ink.npz`` for a plain one).
    """
    if spec.seconds <= 0:
        raise ValueError("--seconds must be positive")
    if not 0.5 <= spec.lux <= 100_000:
        raise ValueError(f"--lux {spec.lux} is outside 0.5..100000")
    if not 0.7 <= spec.f_number <= 32:
        raise ValueError(f"--f-number {spec.f_number} is outside 0.7..32")
    t_wall = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if spec.split not in ("train", "val"):
        raise ValueError(f"split {spec.split!r}: use 'train' or 'val'")
    if spec.simulator != "darkread" and simulator is simulate_events:
        raise ValueError(f"simulator {spec.simulator!r}: pass it as write_recording's simulator "
                         "(darkread.lab.synth.simulators.simulator_for)")
    session = make_session(session_spec(spec), spec.seed)
    seconds = recording_seconds(spec, session)
    rng = np.random.default_rng([spec.seed, 2])

    event_t0, device_t0 = _clock_origins(rng)
    true_offset = event_t0 - device_t0
    written_offset = true_offset + int(round(rng.normal(0.0, 2000.0)))
    calib = replace(session.calib, gaze_to_event_time_offset_us=int(written_offset))

    rows = gaze_rows(session, device_t0, seconds, rng)
    uv = gaze_pixels(session, {k: v[~rows["blink"]] for k, v in rows.items()})
    x0, y0, w, h = reachable_region(uv)
    if spec.full_view:
        x0, y0, w, h = 0, 0, *SENSOR_WH
    elif session.marker_page is not None:
        x0, y0, w, h = union_region((x0, y0, w, h), page_region(session, seconds))
    region = Region.of(session.calib, x0, y0, w, h)
    log.info("simulating region x=%d..%d y=%d..%d (%d px)", x0, x0 + w, y0, y0 + h, w * h)
    signal, background, sensor_doc = simulator(spec, session, region, seconds, rng, progress=progress)
    events = merged_events([signal, background])
    del signal, background
    events["t"] += event_t0

    serial = f"{int(rng.integers(0, 1 << 32)):08x}"
    write_raw(
        out / "events.raw",
        events,
        width=SENSOR_WH[0],
        height=SENSOR_WH[1],
        header_extra={
            "camera_integrator_name": "Prophesee",
            "date": "2026-01-01 00:00:00",
            "generation": "4.2",
            "integrator_name": "Prophesee",
            "plugin_integrator_name": "Prophesee",
            "plugin_name": "hal_plugin_imx636_evk4",
            "sensor_generation": "4.2",
            "serial_number": serial,
            "system_ID": "49",
        },
    )
    uid_bytes = rng.integers(0, 256, 16).astype(np.uint8).tobytes()

    write_gaze_csv(
        out / "general_eye_gaze.csv",
        rows["t_us"],
        rows["left"],
        rows["right"],
        rows["pitch"],
        rows["depth"],
        bounds_rad=0.05,
        session_uid=str(uuid.UUID(bytes=uid_bytes, version=4)),
    )
    save_calibration(out / "calibration.json", calib)
    if session.marker_page is not None:
        save_layout(out / LAYOUT_NAME, session.marker_page)
    else:
        write_page_ink(out / PAGE_INK_NAME, session)
    write_pose_truth(out / POSE_TRUTH_NAME, session, seconds, event_t0)
    _write_gyroscope(out, spec, session, seconds, device_t0)
    (out / "text.txt").write_text(session.page.text, encoding="ascii")
    duration = round(seconds, 3)
    face_family = session.page.font.removesuffix(" Bold")
    meta = {
        "description": spec.description,
        "lux": float(spec.lux),
        "motion": session.scene.motion.level,
        "text_kind": session.kind,
        "font": face_family,
        "font_face": session.page.font,
        "xheight_px": round(session.xheight_px, 2),
        "xheight_px_measured_t0": round(session.scene.xheight_px(0.0), 2),
        "duration_s": duration,
        "text_source": CORPUS_SOURCE if session.kind in ("paragraph", "words") else f"generated ({session.kind})",
        "text_split": spec.split,
        "n_lines": len(session.page.lines),
        "event_count": int(events.size),
        "event_rate_hz": round(events.size / duration, 1),
        "seed": int(spec.seed),
        "simulated_region_xywh": [x0, y0, w, h],
        "sensor": sensor_doc,
        "page": {k: round(float(v), 4) for k, v in session.extras.items()},
        "generator": "darkread.models.synth",
        "sensor_regime": spec.regime,
        "lens_f_number": float(spec.f_number),  # only the grounded regime converts light to the chip through it
        "biases": {"profile": spec.bias_profile, "offsets": profile_offsets(spec.bias_profile)},  # from factory
        "simulator": spec.simulator,  # what turned light into events; "sensor" holds its parameters
        "sensor_profile": spec.sensor_profile,  # the measured profile the sensor was drawn around, if any
    }
    if session.marker_page is not None:
        meta["markers"] = {"layout": LAYOUT_NAME, "pose_truth": POSE_TRUTH_NAME, "n_markers": len(session.marker_page.markers)}
    meta["truth"] = {"pose": POSE_TRUTH_NAME, "ink": LAYOUT_NAME if session.marker_page is not None else PAGE_INK_NAME}
    if spec.full_view:  # (absent: the reachable region simulated, as in every older recording)
        meta["full_view"] = True
    if spec.motion_regime != "standard":  # (absent: the standard draws, as in every older recording)
        meta["motion_regime"] = spec.motion_regime
    if spec.scanpath != "model" or spec.scanpath_file is not None:
        meta["scanpath"] = {"kind": "human", "source": HumanScanpath.load(spec.scanpath_file or SHIPPED).source}
    (out / "meta.json").write_text(json.dumps(meta, indent=2))
    log.info("wrote %s: %d events in %.1f s wall", out, events.size, time.perf_counter() - t_wall)
    return meta
