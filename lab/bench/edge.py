"""The edge loop end to end on the sample recording, in the default inference mode
(``PipelineConfig().infer``, named in every label) with the other one measured beside it in the
same run: ``on-change`` (inference gated by the gaze, one fused view per fixation) and
``every-window`` (a frame per 1600 foveated events, the research mode). Keys:
``edge_realtime_factor``, ``edge_inferences_per_s`` and ``edge_uplink_kbyte_per_s`` are the default
mode's; ``edge_realtime_factor_on_change`` and ``edge_realtime_factor_every_window`` name theirs;
the view latency is on-change's (only it makes views), the event-to-wire latency every-window's.

* Real-time factor (recording seconds per CPU second of a fresh process, spawned for it so no thread
  of an earlier benchmark counts): the whole edge (replay as fast as possible -> ring -> fovea at the gaze ->
  voxel -> U-Net -> frame message encoded) on one core (CPU affinity pinned when the OS allows),
  lossless (every window reconstructed). CPU time rather than wall time because the benchmark host
  is shared; the wall-clock factor is printed beside it. Reference: decoding
  the same file alone (``RawReader``), the ceiling of any replay.
* Event-to-wire latency: replay paced at wall-clock speed through the real uplink to a local
  websocket server that acknowledges every frame (``ack_server.AckServer``); from the arrival of a window's newest event to
  the frame handed to the socket. Reference: inference alone in the same run. In the on-change
  mode the same clock runs from the arrival of the chunk that ended the fixation (the first gaze
  row off it, as the classifier sees it) to its view handed to the socket.
* Uplink bytes per second of reading, paced at 1x, and inferences per second of reading.
* The wearable's mode, on a recording whose page fills the view (``FULL_VIEW_SPEC``: every pixel of
  the sensor simulated, the page's text and edge and a desk around it, head moving, 30 lux, with its
  gyroscope stream; cached in the bench's cache folder, a simulation of several minutes):
  ``edge_realtime_factor_full_view`` is today's mode on it (the IMU ignored, ``[imu] kind = "none"``,
  the whole sensor delivered), ``edge_realtime_factor_imu_roi`` the head's motion from the recording's
  gyroscope with the sensor's ROI on (``sensor_roi = "auto"``) measured on what the camera would
  deliver (``roi_stream``: a first pass records the events inside the ROI in force, a second replays
  only those and is timed; the two make the same frames), ``edge_imu_roi_speedup`` their ratio;
  ``edge_events_decoded_per_s`` and ``_roi`` the events each decodes and hands over per second of
  reading (what crosses USB). A smoke run uses a 0.3-s recording of the reachable region instead.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import multiprocessing
import os
import shutil
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, TypeVar

import cv2
import numpy as np

from darkread.core.image_codec import ImageCodecError, encode_png, read_image
from darkread.core.paths import SAMPLE_RECORDING
from darkread.edge.builder import build_edge
from darkread.edge.config import INFER_MODES, default_infer_mode, load_config, other_infer_mode
from darkread.edge.io.raw import RawReader, read_raw, write_raw
from darkread.edge.io.recording import open_recording
from darkread.edge.reconstruct import default_model_path
from darkread.edge.sources.replay import ReplaySource
from darkread.edge.telemetry import RGB_FRAME_BYTES_ESTIMATE
from darkread.edge.voxel import VoxelConfig
from darkread.lab.bench import BenchContext, Figure
from darkread.lab.bench.ack_server import AckServer
from darkread.lab.bench.roi_stream import Deliveries, record_deliveries, replay_as_delivered, write_delivered
from darkread.models.synth.recording import RecordingSpec, write_recording
from darkread.proto.messages import encode

if TYPE_CHECKING:
    from darkread.edge.frame import FrameResult
    from darkread.edge.sources.replay import ReplaySource
    from darkread.edge.steps import FrameHandler
    from darkread.edge.telemetry import EdgeMetrics
    from darkread.edge.view_fusion import ViewRecord

SMOKE_SECONDS = 1.0  # (the gyroscope is trusted from 0.5 s on: walking or not is decided over its first half second)
T = TypeVar("T")
# glasses at reading distance: 22 lines of 80 characters across the view, the paper's edge and a desk beside it
FULL_VIEW_SPEC = RecordingSpec(
    lux=30.0, motion="normal", kind="paragraph", seconds=3.0, seed=46, font="DejaVu Sans", xheight_px=10.0,
    n_lines=22, line_chars=80, full_view=True, description="a page filling the view (darkread.lab.bench.edge)",
)
SMOKE_VIEW_SPEC = dataclasses.replace(FULL_VIEW_SPEC, seconds=SMOKE_SECONDS, full_view=False, n_lines=3, line_chars=30)
FULL_VIEW = {"imu": {"kind": "none"}, "pipeline": {"sensor_roi": "off"}}  # today's mode: the whole sensor, head motion from it
IMU_ROI = {"imu": {"kind": "recording"}, "pipeline": {"sensor_roi": "auto"}}  # the gyroscope, and the ROI while it is healthy
VIEW_RUNS = ("full_view", "imu_roi_pass1", "imu_roi")  # the runs on the whole-sensor recording


class ModeRun(TypedDict):
    """One mode's best lossless replay."""

    wall_s: float
    cpu_s: float
    recording_s: float
    events_out: float
    frames: int
    views: int
    words_outside_roi: float
    roi_writes: int
    messages_sha256: str  # of every frame's and view's encoded message, in order
    narrowed_after_s: float  # from the first event to the first ROI write (the sensor whole before it; 0: none)
    events_narrowed: float  # events delivered from the first ROI write on


class LosslessRuns(TypedDict):
    pinned: bool
    decode_s: float
    modes: dict[str, ModeRun]


def _recording(ctx: BenchContext) -> Path | None:
    if (SAMPLE_RECORDING / "events.raw").is_file():
        found = SAMPLE_RECORDING
    elif ctx.shared_data is not None and (ctx.shared_data / "sample_recording" / "events.raw").is_file():
        found = ctx.shared_data / "sample_recording"
    else:
        return None
    return _first_seconds(found, ctx.scratch / "smoke_recording", SMOKE_SECONDS) if ctx.smoke else found


def _first_seconds(recording: Path, out: Path, seconds: float) -> Path:
    """A copy of ``recording`` cut to its first ``seconds`` of events (the smoke run's input)."""


    out.mkdir(parents=True, exist_ok=True)
    for name in ("general_eye_gaze.csv", "calibration.json", "text.txt"):
        if (recording / name).is_file():
            shutil.copy(recording / name, out / name)
    raw = read_raw(recording / "events.raw")
    t = raw.events["t"]
    write_raw(out / "events.raw", raw.events[t < t[0] + int(seconds * 1e6)], width=raw.header.width, height=raw.header.height)
    return out


def _model(ctx: BenchContext) -> Path | None:
    """The shipped model, else a stand-in with its I/O (noted), else None."""

    if default_model_path().is_file():
        return None
    try:
        import onnx
        from onnx import TensorProto, helper
    except ImportError:
        raise RuntimeError("no shipped model and no `onnx` package to build a stand-in") from None

    bins, height, width = VoxelConfig().shape  # the window the shipped model was trained for
    x = helper.make_tensor_value_info("voxel", TensorProto.FLOAT, ["batch", bins, height, width])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["batch", 1, height, width])
    weight = helper.make_tensor("w", TensorProto.FLOAT, [1, bins, 3, 3], np.full(bins * 9, 0.1, np.float32).tolist())
    node = helper.make_node("Conv", ["voxel", "w"], ["logits"], pads=[1, 1, 1, 1])
    model = helper.make_model(
        helper.make_graph([node], "standin", [x], [y], initializer=[weight]),
        opset_imports=[helper.make_opsetid("", 17)],
    )
    model.ir_version = 8
    path = ctx.scratch / "standin.onnx"
    onnx.save(model, str(path))
    ctx.notes.append("edge: the shipped binary_unet.onnx is missing; timed with a one-conv stand-in model")
    return path


@contextlib.contextmanager
def _one_core() -> Iterator[bool]:
    getter = getattr(os, "sched_getaffinity", None)
    if getter is None:
        yield False
        return
    before = getter(0)
    try:
        os.sched_setaffinity(0, {min(before)})
    except OSError:
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setaffinity(0, before)


def _decode_only_cpu_s(raw_path: Path) -> float:

    started = time.process_time()
    for _ in RawReader(raw_path, chunk_bytes=1 << 18):
        pass
    return time.process_time() - started


def _run_edge(
    recording: Path, model: Path | None, speed: float, on_frame: FrameHandler | None = None, uplink_url: str = "",
    infer: str = "on-change", mode: dict[str, dict[str, str]] | None = None,
    tap: Callable[[ReplaySource], Deliveries] | None = None,
) -> tuple[float, float, ReplaySource, EdgeMetrics]:
    """(wall s, process CPU s, source, metrics) of one replay through the edge ``build_edge`` wires.

    ``speed`` 0 replays as fast as possible (lossless); ``on_frame`` takes the frames instead of
    the uplink (then ``uplink_url`` is unused); ``mode``: the ``[imu]`` and ``[pipeline]`` settings
    of the mode run (``FULL_VIEW``, ``IMU_ROI``; none: the defaults); ``tap`` wraps the replay before
    it starts (``roi_stream``).
    """
    mode = mode or {}
    config = load_config(None, environ={}, overrides={
        "source": {"kind": "replay", "path": str(recording), "speed": speed},
        "gaze": {"kind": "recording"},
        "imu": mode.get("imu", {}),
        "pipeline": {"threads": 1, "infer": infer, **({"model": str(model)} if model else {}), **mode.get("pipeline", {})},
        "uplink": {"url": uplink_url or "ws://127.0.0.1:1/v1/stream", "device_id": "bench", "spool_dir": ":memory:"},
        "metrics": {"log_every_s": 3600.0},
    })
    edge = build_edge(config, on_frame=on_frame)
    source = edge.source
    assert isinstance(source, ReplaySource)  # the config above asks for a replay
    if tap is not None:
        tap(source)
    started, cpu_started = time.perf_counter(), time.process_time()
    edge.startup(wait_connected_s=5.0)
    source.wait()
    edge.pipeline.stop()
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu_started
    edge.shutdown(5.0)
    if edge.pipeline.error is not None:
        raise RuntimeError(f"edge loop failed: {edge.pipeline.error}")
    return wall, cpu, source, edge.metrics


def _rgb_frame_bytes(recording: Path) -> tuple[int, str]:
    """Bytes of one 2880x2880 RGB PNG: the recording's snapshot upscaled and encoded, or the estimate."""

    rgb = recording / "rgb.png"
    if rgb.is_file():


        try:
            image = read_image(rgb, colour=True)
            return len(encode_png(cv2.resize(image, (2880, 2880), interpolation=cv2.INTER_CUBIC))), "measured"
        except ImageCodecError:
            pass
    return RGB_FRAME_BYTES_ESTIMATE, "estimated"


class _Encoded:
    """The uplink's work on each message, without a socket (``on_frame``); the messages' digest kept."""

    def __init__(self) -> None:
        self._sha = hashlib.sha256()

    def __call__(self, frame: FrameResult | ViewRecord, arrival: float) -> None:
        self._sha.update(encode(frame.to_message()))

    @property
    def digest(self) -> str:
        return self._sha.hexdigest()


def _mode_run(recording: Path, model: Path | None, infer: str, mode: dict[str, dict[str, str]] | None = None,
              tap: Callable[[ReplaySource], Deliveries] | None = None) -> ModeRun:
    """One lossless replay of ``recording`` in ``mode`` as plain numbers."""
    encoded = _Encoded()
    wall, cpu, source, metrics = _run_edge(recording, model, 0.0, on_frame=encoded, infer=infer, mode=mode, tap=tap)
    return {"wall_s": wall, "cpu_s": cpu, "recording_s": source.stats["recording_s"],
            "events_out": source.stats["events_out"], "frames": metrics.totals["frames"],
            "views": metrics.totals["views"], "words_outside_roi": source.stats["words_outside_roi"],
            "roi_writes": metrics.totals["roi_writes"], "messages_sha256": encoded.digest,
            "narrowed_after_s": 0.0, "events_narrowed": 0.0}


def _lossless(recording: Path, model: Path | None, repeats: int, view: Path | None = None, scratch: Path | None = None) -> LosslessRuns:
    """The decode-only reference and each mode's best lossless replay on one pinned core (plain numbers);
    with ``view`` (a whole-sensor recording with its gyroscope stream) also, on it, today's default
    mode (``modes["full_view"]``) and the wearable's (``modes["imu_roi"]``: the second pass of
    ``roi_stream`` on what the first, ``modes["imu_roi_pass1"]``, delivered; written under ``scratch``)."""
    with _one_core() as pinned:
        decode_s = min(_decode_only_cpu_s(recording / "events.raw") for _ in range(repeats))
        modes: dict[str, ModeRun] = {}
        runs: list[tuple[str, Path, str, dict[str, dict[str, str]] | None]] = [(m, recording, m, None) for m in INFER_MODES]
        if view is not None and scratch is not None:
            runs.append(("full_view", view, default_infer_mode(), FULL_VIEW))
            kept: list[Deliveries] = []

            def keep(source: ReplaySource) -> Deliveries:
                kept.append(record_deliveries(source))
                return kept[-1]

            modes["imu_roi_pass1"] = _mode_run(view, model, default_infer_mode(), IMU_ROI, keep)
            deliveries = first_pass = kept.pop()
            events = deliveries.events
            if deliveries.roi_writes and events.shape[0]:  # the steady state: once the sensor is narrowed
                first_write = deliveries.roi_writes[0][0]
                modes["imu_roi_pass1"]["narrowed_after_s"] = (first_write - int(events["t"][0])) / 1e6
                modes["imu_roi_pass1"]["events_narrowed"] = float(np.count_nonzero(events["t"] > first_write))
            delivered = write_delivered(view, deliveries, scratch / "delivered_through_roi")
            first_pass.chunks = []  # (its ROI writes and their times are what the second pass needs)
            del deliveries, events
        for name, path, infer, mode in runs:
            modes[name] = min((_mode_run(path, model, infer, mode) for _ in range(repeats)), key=lambda r: r["cpu_s"])
        if view is not None and scratch is not None:
            as_delivered = functools.partial(replay_as_delivered, first=first_pass)
            modes["imu_roi"] = min((_mode_run(delivered, model, default_infer_mode(), IMU_ROI, as_delivered)
                                    for _ in range(repeats)), key=lambda r: r["cpu_s"])
    return {"pinned": pinned, "decode_s": decode_s, "modes": modes}


def _cache_folder(ctx: BenchContext) -> Path:
    """Where simulated inputs are kept between runs (the scratch folder in a smoke run)."""
    return ctx.scratch if ctx.smoke or ctx.cache is None else ctx.cache


def _simulation_key(spec: RecordingSpec) -> str:
    """The spec and the simulator's source: a cached recording is reused only while both are the same."""
    sha = hashlib.sha256(json.dumps(dataclasses.asdict(spec), sort_keys=True).encode())
    synth = Path(write_recording.__code__.co_filename).parent
    for source in sorted(synth.glob("*.py")):
        sha.update(source.read_bytes())
    return sha.hexdigest()[:16]


def _view_recording(ctx: BenchContext) -> Path:
    """The whole-sensor recording (``FULL_VIEW_SPEC``; in a smoke run ``SMOKE_VIEW_SPEC``), simulated
    once and kept in the cache folder."""
    spec = SMOKE_VIEW_SPEC if ctx.smoke else FULL_VIEW_SPEC
    out = _cache_folder(ctx) / f"edge_view_{_simulation_key(spec)}"
    if not (out / "meta.json").is_file():  # written last: a folder without it is an interrupted simulation
        ctx.notes.append(f"edge: simulating {out.name} ({spec.seconds:g} s{', the whole sensor' if spec.full_view else ''})")
        shutil.rmtree(out, ignore_errors=True)
        write_recording(out, spec, progress=False)
    if ctx.smoke:
        ctx.notes.append("edge: smoke run, a 0.3-s recording of the reachable region stands in for the full view")
    return out


def _in_fresh_process(function: Callable[..., T], *args: object) -> T:
    """``function(*args)`` in a new interpreter (spawned, not forked: nothing of this process comes along)."""

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(function, *args).result()


def run(ctx: BenchContext) -> list[Figure]:

    recording = _recording(ctx)
    if recording is None:
        ctx.notes.append("edge: no sample recording (darkread/data or ../shared); skipped")
        return []
    model = _model(ctx)
    meta = open_recording(recording).meta
    repeats = ctx.runs(3, 1)
    # in a fresh process: threads left running by the benchmarks before this one (a simulator's
    # pool, a server) would count in this process's CPU time and are not pinned with it
    view = _view_recording(ctx)
    lossless_runs = _in_fresh_process(_lossless, recording, model, repeats, view, ctx.scratch)
    if not lossless_runs["pinned"]:
        ctx.notes.append("edge: could not pin to one core; the real-time factor used all cores")
    decode_s = lossless_runs["decode_s"]
    lossless = lossless_runs["modes"]
    default = default_infer_mode()
    other = other_infer_mode(default)
    span_s = lossless[default]["recording_s"]
    # the whole-sensor recording's length for its runs (the second pass's file may end a few us earlier)
    spans = {mode: lossless["full_view"]["recording_s"] if mode in VIEW_RUNS else span_s for mode in lossless}
    rtf = {mode: spans[mode] / run["cpu_s"] for mode, run in lossless.items()}  # CPU seconds: the host is shared
    decoded = {mode: run["events_out"] / spans[mode] for mode, run in lossless.items()}
    inferences = {mode: run["frames"] for mode, run in lossless.items()}
    views = lossless["on-change"]["views"]
    wall = {mode: spans[mode] / run["wall_s"] for mode, run in lossless.items()}

    paced = {}
    for mode in INFER_MODES:
        server = AckServer()
        try:
            paced[mode] = _run_edge(recording, model, 1.0, uplink_url=server.url, infer=mode)[3]
        finally:
            server.close()
    sent_kb_s = {mode: m.totals["bytes_sent"] / 1e3 / span_s for mode, m in paced.items()}
    raw_kb_s = (recording / "events.raw").stat().st_size / 1e3 / span_s
    rgb_bytes, rgb_how = _rgb_frame_bytes(recording)
    view_latency = np.fromiter(paced["on-change"].latency_ms, np.float64)
    latency = np.fromiter(paced["every-window"].latency_ms, np.float64)
    inference = np.fromiter(paced["every-window"].inference_ms, np.float64)
    rate = meta.get("event_rate_hz", lossless[default]["events_out"] / max(span_s, 1e-9))
    decode_ref = f"decode only {span_s / decode_s:.0f}x"
    infer_ref = f"inference alone p50 {np.percentile(inference, 50):.2f} ms, p99 {np.percentile(inference, 99):.2f} ms"
    made = {"on-change": f"{views} views of {inferences['on-change']} frames", "every-window": f"{inferences['every-window']} frames"}
    sent = {"on-change": "views", "every-window": "frames"}
    return [
        Figure(
            "edge_realtime_factor", rtf[default],
            f"edge real-time factor, 1 core CPU time, lossless, default mode {default} ({made[default]}, {rate / 1e3:.0f} kev/s)",
            reference=f"{other} {rtf[other]:.2f}x ({made[other]}); {decode_ref}; wall clock {wall[default]:.1f}x",
            goal=">= 20x",
        ),
        Figure("edge_realtime_factor_on_change", rtf["on-change"], "edge real-time factor, on-change mode",
               reference=f"wall clock {wall['on-change']:.1f}x" + (" (the default)" if default == "on-change" else "")),
        Figure("edge_realtime_factor_every_window", rtf["every-window"], "edge real-time factor, every-window mode",
               reference=f"wall clock {wall['every-window']:.1f}x" + (" (the default)" if default == "every-window" else "")),
        Figure("edge_decode_realtime_factor", span_s / decode_s, "RAW decode alone, real-time factor", reference="(reference)"),
        *_view_figures(lossless, rtf, decoded, wall, default, view),
        Figure(
            "edge_inferences_per_s", inferences[default] / span_s, f"inferences per second of reading, default mode {default}",
            reference=f"{other} {inferences[other] / span_s:.1f}/s; views {views / span_s:.1f}/s",
        ),
        Figure(
            "edge_uplink_kbyte_per_s", sent_kb_s[default], f"uplink bandwidth, default mode {default} ({sent[default]}), paced at 1x",
            reference=f"{other} {sent[other]} {sent_kb_s[other]:.1f} kB/s; raw EVT3 stream {raw_kb_s:.0f} kB/s; "
                      f"one 2880x2880 RGB PNG {rgb_bytes / 1e3:.0f} kB ({rgb_how})",
            goal="<= 15",
        ),
        Figure(
            "edge_view_latency_p99_ms", float(np.percentile(view_latency, 99)) if view_latency.size else float("nan"),
            f"fixation end to its view on the wire p99, on-change, paced at 1x ({view_latency.size} views)",
            reference=f"p50 {np.percentile(view_latency, 50) if view_latency.size else float('nan'):.1f} ms; {infer_ref}",
            goal="<= 50 ms",
        ),
        Figure(
            "edge_latency_p50_ms", float(np.percentile(latency, 50)),
            f"event-to-wire latency p50, every-window, paced at 1x ({latency.size} frames)", reference=infer_ref,
        ),
        Figure("edge_latency_p99_ms", float(np.percentile(latency, 99)), "event-to-wire latency p99, every-window, paced at 1x",
               reference=infer_ref, goal="<= 20 ms"),
    ]


def _view_figures(lossless: dict[str, ModeRun], rtf: dict[str, float], decoded: dict[str, float], wall: dict[str, float],
                  default: str, view: Path) -> list[Figure]:
    """Today's mode and the wearable's on the whole-sensor recording, in the same run."""
    full, roi, first = lossless["full_view"], lossless["imu_roi"], lossless["imu_roi_pass1"]
    same = roi["messages_sha256"] == first["messages_sha256"] and (roi["frames"], roi["views"]) == (first["frames"], first["views"])
    passes = (f"pass 2's {roi['frames']} frames and {roi['views']} views identical to pass 1's" if same else
              f"pass 2 DIFFERS from pass 1 ({roi['frames']}/{roi['views']} against {first['frames']}/{first['views']} frames/views)")
    made = f"{full['views']} views of {full['frames']} frames"
    steady = first["events_narrowed"] / max(full["recording_s"] - first["narrowed_after_s"], 1e-9)
    return [
        Figure("edge_realtime_factor_full_view", rtf["full_view"],
               f"edge real-time factor, {default}, page filling the view ({view.name}), whole sensor, head motion from the events",
               reference=f"{made}; {decoded['full_view'] / 1e3:.0f} kev/s; wall clock {wall['full_view']:.1f}x"),
        Figure("edge_realtime_factor_imu_roi", rtf["imu_roi"],
               f"edge real-time factor, {default}, same recording, head motion from its gyroscope and the sensor ROI on, "
               "replaying what the sensor delivered",
               reference=f"{roi['views']} views of {roi['frames']} frames, {roi['roi_writes']} ROI writes; {passes}; "
                         f"replaying the whole file with the ROI in the decoder {rtf['imu_roi_pass1']:.1f}x; wall clock {wall['imu_roi']:.1f}x",
               goal=">= 40x"),
        Figure("edge_imu_roi_speedup", rtf["imu_roi"] / rtf["full_view"], "wearable's mode over today's on the page filling the view",
               reference=f"{rtf['imu_roi']:.1f}x / {rtf['full_view']:.1f}x", goal=">= 2x"),
        Figure("edge_events_decoded_per_s", decoded["full_view"], f"events decoded and handed over per s of reading, {default}, whole sensor",
               reference=f"{int(full['events_out']):,} events on the page filling the view"),
        Figure("edge_events_decoded_per_s_roi", decoded["imu_roi"], "events decoded and handed over per s of reading, sensor ROI on",
               reference=f"whole sensor {decoded['full_view']:.0f}/s ({decoded['full_view'] / max(decoded['imu_roi'], 1e-9):.1f}x more); "
                         f"the whole sensor until the first ROI write {first['narrowed_after_s'] * 1e3:.0f} ms in, "
                         f"{steady:.0f}/s from it on ({decoded['full_view'] / max(steady, 1e-9):.1f}x fewer); "
                         f"pass 1 walked {int(first['words_outside_roi']):,} file words outside the ROI",
               goal=">= 10x below the whole sensor's"),
    ]
