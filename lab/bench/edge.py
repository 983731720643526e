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
* The wearable's mode (``edge_realtime_factor_imu_roi``, ``edge_events_decoded_per_s_roi``): the
  same lossless replay with the head's motion known and the sensor's ROI on (``sensor_roi = "auto"``),
  beside today's (``edge_realtime_factor``, ``edge_events_decoded_per_s``: events the replay decodes
  and hands over per second of reading, what would cross USB). Until the IMU stream exists the known
  motion is the simulator's pose of the sample (``lab.eval.true_motion``; the sample regenerated with
  its truth files, the same events byte for byte); it will switch to the recording's IMU stream.
"""

from __future__ import annotations

import contextlib
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
from darkread.lab.eval.true_motion import TrueHeadMotion
from darkread.models.synth.make_sample import SAMPLE_SPEC
from darkread.models.synth.recording import write_recording
from darkread.proto.messages import encode

if TYPE_CHECKING:
    from darkread.edge.frame import FrameResult
    from darkread.edge.sources.replay import ReplaySource
    from darkread.edge.steps import FrameHandler
    from darkread.edge.telemetry import EdgeMetrics
    from darkread.edge.view_fusion import ViewRecord

SMOKE_SECONDS = 0.3
T = TypeVar("T")


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
    infer: str = "on-change", known_motion: TrueHeadMotion | None = None,
) -> tuple[float, float, ReplaySource, EdgeMetrics]:
    """(wall s, process CPU s, source, metrics) of one replay through the edge ``build_edge`` wires.

    ``speed`` 0 replays as fast as possible (lossless); ``on_frame`` takes the frames instead of
    the uplink (then ``uplink_url`` is unused).
    """

    config = load_config(None, environ={}, overrides={
        "source": {"kind": "replay", "path": str(recording), "speed": speed},
        "gaze": {"kind": "recording"},
        "pipeline": {"threads": 1, "infer": infer, **({"model": str(model)} if model else {})},
        "uplink": {"url": uplink_url or "ws://127.0.0.1:1/v1/stream", "device_id": "bench", "spool_dir": ":memory:"},
        "metrics": {"log_every_s": 3600.0},
    })
    edge = build_edge(config, on_frame=on_frame, known_motion=known_motion)
    source = edge.source
    assert isinstance(source, ReplaySource)  # the config above asks for a replay
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


def _lossless(recording: Path, model: Path | None, repeats: int, posed: Path | None = None) -> LosslessRuns:
    """The decode-only reference and each mode's best lossless replay on one pinned core (plain numbers);
    with ``posed`` (the recording with its simulator truth) also the default mode with the head's
    motion known and the ROI on, as ``modes["imu_roi"]``."""
    known = TrueHeadMotion.from_recording(posed) if posed is not None else None
    with _one_core() as pinned:
        decode_s = min(_decode_only_cpu_s(recording / "events.raw") for _ in range(repeats))
        modes: dict[str, ModeRun] = {}
        runs: list[tuple[str, Path, str, TrueHeadMotion | None]] = [(mode, recording, mode, None) for mode in INFER_MODES]
        if posed is not None:
            runs.append(("imu_roi", posed, default_infer_mode(), known))
        for name, path, mode, motion in runs:
            wall, cpu, source, metrics = min(
                (_run_edge(path, model, 0.0, on_frame=_encode_only, infer=mode, known_motion=motion) for _ in range(repeats)),
                key=lambda r: r[1],
            )
            modes[name] = {"wall_s": wall, "cpu_s": cpu, "recording_s": source.stats["recording_s"],
                           "events_out": source.stats["events_out"], "frames": metrics.totals["frames"],
                           "views": metrics.totals["views"], "words_outside_roi": source.stats["words_outside_roi"],
                           "roi_writes": metrics.totals["roi_writes"]}
    return {"pinned": pinned, "decode_s": decode_s, "modes": modes}


def _posed_sample(recording: Path, ctx: BenchContext) -> Path | None:
    """The sample regenerated with the simulator's truth (pose_truth.npz) when its events come out
    byte for byte the shipped ones; None (noted) otherwise or in a smoke run."""
    if ctx.smoke:
        ctx.notes.append("edge: smoke run, no imu_roi replay (the sample's truth takes a simulation)")
        return None
    out = ctx.scratch / "sample_with_truth"
    write_recording(out, SAMPLE_SPEC, progress=False)
    if (out / "events.raw").read_bytes() != (recording / "events.raw").read_bytes():
        ctx.notes.append("edge: the regenerated sample differs from the shipped one; no imu_roi figures")
        return None
    return out


def _encode_only(frame: FrameResult | ViewRecord, arrival: float) -> None:  # the uplink's work on a message, without a socket

    encode(frame.to_message())


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
    posed = _posed_sample(recording, ctx)
    lossless_runs = _in_fresh_process(_lossless, recording, model, repeats, posed)
    if not lossless_runs["pinned"]:
        ctx.notes.append("edge: could not pin to one core; the real-time factor used all cores")
    decode_s = lossless_runs["decode_s"]
    lossless = lossless_runs["modes"]
    default = default_infer_mode()
    other = other_infer_mode(default)
    span_s = lossless[default]["recording_s"]
    rtf = {mode: span_s / run["cpu_s"] for mode, run in lossless.items()}  # CPU seconds: the host is shared
    decoded = {mode: run["events_out"] / span_s for mode, run in lossless.items()}
    inferences = {mode: run["frames"] for mode, run in lossless.items()}
    views = lossless["on-change"]["views"]
    wall = {mode: span_s / run["wall_s"] for mode, run in lossless.items()}

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
        Figure("edge_events_decoded_per_s", decoded[default], f"events decoded and handed over per s of reading, {default}, whole sensor",
               reference=f"{int(lossless[default]['events_out']):,} events in {span_s:.2f} s"),
        *_imu_roi_figures(lossless, rtf, decoded, default),
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


def _imu_roi_figures(lossless: dict[str, ModeRun], rtf: dict[str, float], decoded: dict[str, float], default: str) -> list[Figure]:
    """The wearable's mode beside today's (none when it did not run)."""
    if "imu_roi" not in lossless:
        return []
    run = lossless["imu_roi"]
    skipped = run["words_outside_roi"]
    return [
        Figure("edge_realtime_factor_imu_roi", rtf["imu_roi"],
               f"edge real-time factor, {default}, head motion known (the simulator's pose until the IMU stream) and the sensor ROI on",
               reference=f"today's {rtf[default]:.2f}x ({rtf['imu_roi'] / rtf[default]:.2f}x of it); {run['frames']} frames, "
                         f"{run['views']} views, {run['roi_writes']} ROI writes",
               goal=">= 40x and >= 2x today's"),
        Figure("edge_events_decoded_per_s_roi", decoded["imu_roi"], "events decoded and handed over per s of reading, sensor ROI on",
               reference=f"whole sensor {decoded[default]:.0f}/s ({decoded[default] / max(decoded['imu_roi'], 1e-9):.1f}x more); "
                         f"{int(skipped):,} file words skipped",
               goal=">= 10x below the whole sensor's"),
    ]
