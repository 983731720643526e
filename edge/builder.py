"""``build_edge(config)``: the one place the edge is wired, for the daemon, ``darkread read`` and the bench.

Like uvicorn's ``Config.load()``, building opens what can fail early (the recording or the camera,
the gaze feed's port, the model, the spool) and starts nothing; :class:`Edge` is the application
the :class:`~darkread.edge.daemon.Daemon` runs: ``startup`` starts the threads, ``tick`` does the
periodic duties, ``shutdown`` drains within a deadline. The window size and bin count come from
the model (``Reconstructor.voxel``) and reach the pipeline, the uplink's ``hello`` and nothing else.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from darkread.core.errors import DarkreadError
from darkread.core.redact import redact
from darkread.edge.bias_control import BiasController, profile_named
from darkread.edge.config import EdgeConfig, GazeConfig, ImuConfig, PipelineConfig, SensorConfig, SourceConfig
from darkread.edge.errors import RunError, SpoolError, UndeliveredError
from darkread.edge.frame import FrameResult, Infer
from darkread.edge.gaze import GazeLookup
from darkread.edge.head_motion import KnownHeadMotion
from darkread.edge.io.calibration import Calibration
from darkread.edge.pipeline import Pipeline
from darkread.edge.reconstruct import Reconstructor
from darkread.edge.ring import EventRing
from darkread.edge.sources.base import EventSource
from darkread.edge.sources.evk4.bias_profiles import FACTORY, profile_offsets
from darkread.edge.steps import FrameHandler, Step
from darkread.edge.steps.every_window import EveryWindowStep
from darkread.edge.steps.on_change import OnChangeStep
from darkread.edge.telemetry import EdgeMetrics, MetricsServer
from darkread.edge.view_fusion import ViewRecord
from darkread.edge.voxel import VoxelConfig
from darkread.edge.windows import Windows

logger = logging.getLogger(__name__)


@dataclass
class Edge:
    """The wired edge: source, gaze, reconstructor, pipeline and where frames go (uplink, pages, or a caller)."""

    config: EdgeConfig
    source: EventSource
    pipeline: Pipeline
    reconstructor: Reconstructor
    metrics: EdgeMetrics
    uplink: Any = None  # None when frames go to the caller
    pages: Any = None  # pages mode: the PageBuilder
    feeds: list[Any] = field(default_factory=list)  # live gaze feeds, started and stopped with the edge
    _metrics_server: MetricsServer | None = field(default=None, init=False)
    left_behind: str = field(default="", init=False)  # after shutdown: what the spool still held, in words
    undelivered: str = field(default="", init=False)  # after shutdown: why, and where those messages are
    _last_log: float = field(default_factory=time.monotonic, init=False)

    # -- the Service the daemon runs ---------------------------------------------------------
    def startup(self, wait_connected_s: float = 0.0) -> str:
        """Start the threads; ``wait_connected_s`` first gives the uplink that long to reach the cloud
        (frames spool meanwhile anyway; a benchmark waits so its first frames are not timed in a queue)."""
        cfg = self.config
        if cfg.metrics.port:
            self._metrics_server = MetricsServer(self.metrics, cfg.metrics.host, cfg.metrics.port)
            self._metrics_server.start()
        if self.uplink is not None:
            self.uplink.start()
            if wait_connected_s > 0:
                self.uplink.connected.wait(wait_connected_s)
        for feed in self.feeds:
            feed.start()
        self.pipeline.start()
        target = (
            f"sending {cfg.uplink.mode} to {redact(cfg.uplink.url)} (session {self.uplink.session_id}, "
            f"spool {self.uplink.spool.where})"
            if self.uplink is not None else "frames to the caller"
        )
        return (
            f"{cfg.source.kind} {self.source.width}x{self.source.height} open, "
            f"model {self.reconstructor.path.name} warm, {target}"
        )

    def tick(self) -> str | None:
        _raise_failure("reconstruction loop", self.pipeline.error)
        _raise_failure("event source", getattr(self.source, "error", None))
        if self.uplink is not None and self.uplink.fatal_error:
            _raise_failure("uplink", self.uplink.failure)
            raise RunError(self.uplink.fatal_error)
        if self.pages is not None and self.pages.due():
            self._send_page()
        if time.monotonic() - self._last_log < self.config.metrics.log_every_s:
            return None
        self._last_log = time.monotonic()
        snap = self.metrics.snapshot()
        logger.info("%s", snap.log_line())
        if self.uplink is None:
            return snap.status_line()
        state = "connected" if self.uplink.connected.is_set() else f"offline ({self.uplink.last_error or 'connecting'})"
        return f"{snap.status_line()}, spool {snap.spool_depth}, uplink {state}"

    def finished(self) -> bool:
        finished = getattr(self.source, "finished", None)
        return bool(finished is not None and finished.is_set()) or not self.pipeline.running

    def verify(self) -> None:
        """After a run that ended by itself: raise what failed while draining, a replay that looked
        corrupt, or one that produced no frames (a recording that cannot be read is not a success)."""
        self.tick()
        problems = getattr(self.source, "problems", [])
        if problems:
            raise RunError(f"{self.config.source.path} does not look like a valid recording: {'; '.join(problems)}")
        totals = self.metrics.totals
        if self.config.source.kind == "replay" and totals["frames"] == 0:
            if totals["events_in"] == 0:
                why = "no events decoded"
            elif totals["events_foveated"] == 0:
                why = f"{int(totals['events_in']):,} events, none inside the gaze window (no valid gaze on the sensor?)"
            else:
                why = f"{int(totals['events_foveated']):,} events inside the gaze window, too few for a frame"
            raise RunError(f"the replay of {self.config.source.path} produced no frames: {why}")

    def shutdown(self, timeout_s: float) -> bool:
        """Stop the source (the last frame comes from what is buffered), send the last page, drain."""
        self.pipeline.stop()
        for feed in self.feeds:
            feed.stop()
        if self.pages is not None:
            self._send_page(final=True)
        drained = True
        if self.uplink is not None:
            drained = self.uplink.stop(drain_timeout_s=timeout_s)
            self.left_behind = self.uplink.left_behind()
            self.undelivered = self.uplink.undelivered(timeout_s) if not drained else ""
            self.uplink.spool.close()
        if self._metrics_server is not None:
            self._metrics_server.stop()
        close = getattr(self.source, "close", None)
        if close is not None:
            close()
        logger.info("final: %s", self.metrics.snapshot().log_line())
        return drained

    def with_left_behind(self, failure: DarkreadError) -> DarkreadError:
        """``failure`` (what ended the run) with what the spool still held after the shutdown, so
        the run's one error line says both; its exit status stays ``failure``'s."""
        if not self.left_behind:
            return failure
        wrapped = RunError(f"{failure}; {self.left_behind}")
        wrapped.exit_code = failure.exit_code
        return wrapped

    def undelivered_error(self) -> UndeliveredError:
        """After a run that ended without every message acknowledged: why, and where they are."""
        return UndeliveredError(self.undelivered or self.left_behind or "messages were left undelivered")

    def _send_page(self, final: bool = False) -> None:
        message = self.pages.message(self.pipeline.ring.newest_t or 0, final=final)
        if message is not None:
            self.uplink.submit(message)
            self.metrics.add("pages")


def build_edge(
    config: EdgeConfig,
    *,
    watchdog: Callable[[], object] | None = None,
    on_frame: FrameHandler | None = None,
    known_motion: KnownHeadMotion | None = None,
) -> Edge:
    """Wire the edge described by ``config``; nothing runs until ``Edge.startup()``.

    ``watchdog`` is called from the processing loop while events flow (systemd's watchdog ping);
    ``on_frame``, when given, receives the frames instead of an uplink (the bench's encode-only run);
    ``known_motion``, the head's motion from elsewhere instead of measured from the events
    (``edge.head_motion``); without it, the gyroscope's (``[imu]``: the replayed recording's
    ``closed_loop_trajectory.csv`` when it has one, or a live feed), searched around by the deblur
    with the event tracker beside it (``edge.imu_motion``).
    """
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.binning import warm_up as warm_up_binning
    from darkread.edge.io.evt3 import warm_up as warm_up_decoder

    metrics = EdgeMetrics()
    with contextlib.ExitStack() as undo:  # a failure half-way closes what was opened
        coarse = STEPS[config.pipeline.infer].replay_grid_us is not None
        source, calibration, gaze_track, imu_track, profile = _open_source(config.source, metrics, config.sensor, coarse=coarse)
        close = getattr(source, "close", None)
        if close is not None:
            undo.callback(close)
        feeds: list[Any] = []
        gaze = _open_gaze(config.gaze, calibration, gaze_track, feeds)
        if known_motion is None:
            known_motion = _open_imu(config.imu, calibration, imu_track, feeds)
        for feed in feeds:
            undo.callback(feed.stop)
        warm_up_decoder()  # READY only once the first chunk can be decoded without a JIT pause ...
        warm_up_binning()  # ... and counted (head motion, deblur)
        reconstructor = Reconstructor(config.pipeline.model or None, threads=config.pipeline.threads)
        voxel = reconstructor.voxel
        uplink = pages = None
        if on_frame is None:
            uplink = _open_uplink(config, metrics, (source.width, source.height), (voxel.height, voxel.width))
            undo.callback(uplink.spool.close)
            if config.uplink.mode == "pages":
                # lazy: only the parts this configuration uses load (USB, websockets, numba)
                from darkread.edge.pages import PageBuilder

                pages = PageBuilder(config.uplink.page_every_s)
                on_frame = _to_pages(pages)
            else:
                on_frame = _to_uplink(uplink)
        settings = config.pipeline
        if config.source.kind == "replay" and config.source.speed == 0:
            settings = dataclasses.replace(settings, lossless=True)  # no clock to keep up with: make every window
        light = open_bias_control(config.sensor, source, metrics, profile)
        pipeline = build_pipeline(source, gaze, reconstructor, on_frame, settings, voxel, metrics, watchdog=watchdog,
                                  known_motion=known_motion, light=light, configured_lux=config.sensor.lux)
        undo.pop_all()
    return Edge(config, source, pipeline, reconstructor, metrics, uplink=uplink, pages=pages, feeds=feeds)


STEPS: dict[str, type[OnChangeStep] | type[EveryWindowStep]] = {"on-change": OnChangeStep, "every-window": EveryWindowStep}
"""``[pipeline] infer`` -> the pipeline's step (``edge.steps``)."""


def build_pipeline(
    source: EventSource,
    gaze: GazeLookup,
    infer: Infer,
    on_frame: FrameHandler,
    settings: PipelineConfig = PipelineConfig(),
    voxel: VoxelConfig = VoxelConfig(),
    metrics: EdgeMetrics | None = None,
    *,
    watchdog: Callable[[], object] | None = None,
    known_motion: KnownHeadMotion | None = None,
    light: BiasController | None = None,
    configured_lux: float = 0.0,
) -> Pipeline:
    """The pipeline ``settings`` describe: its windows on a fresh ring, and the step ``infer`` names,
    chosen here once. ``known_motion``: the head's motion from elsewhere (``edge.head_motion``);
    ``light``: the controller of the sensor's bias profile (``edge.bias_control``), whose light
    estimate each frame and view carries; without one, ``configured_lux`` (``[sensor] lux``, 0: none)."""
    windows = Windows(EventRing(settings.ring_capacity), source, gaze, infer, settings, voxel, metrics or EdgeMetrics(),
                      known_motion, light_probe=light.wants_whole if light is not None else None,
                      light_level=light_reading(light, configured_lux))
    step: Step = STEPS[settings.infer](windows, settings, on_frame)
    return Pipeline(source, windows, step, settings, watchdog=watchdog, light=light)


def light_reading(light: BiasController | None, configured_lux: float = 0.0) -> Callable[[], float | None] | None:
    """What a frame or view says of the light at the page: the controller's latest estimate (None
    until its first), else a configured light level; None when neither exists."""
    if light is not None:
        return lambda: light.lux
    if configured_lux > 0:
        return lambda: configured_lux
    return None


def _raise_failure(part: str, error: BaseException | None) -> None:
    """Raise what failed in ``part``'s thread: a SpoolError as it is (it names the spool, the cause
    and its own exit status), anything else as a RunError saying which part failed."""
    if isinstance(error, SpoolError):
        raise error
    if error is not None:
        raise RunError(f"{part} failed: {error}") from error


def _to_uplink(uplink: Any) -> FrameHandler:
    def submit(frame: FrameResult | ViewRecord, arrival: float) -> None:
        uplink.submit(frame.to_message(), submitted_at=arrival)

    return submit


def _to_pages(pages: Any) -> FrameHandler:
    def add(frame: FrameResult | ViewRecord, arrival: float) -> None:
        pages.add(frame)

    return add


def open_bias_control(cfg: SensorConfig, source: EventSource, metrics: EdgeMetrics, profile: str | None) -> BiasController | None:
    """The controller of the sensor's bias profile with ``[sensor] profile = "auto"`` (a fixed profile
    is written when the camera opens); ``profile``: the one the source runs now (None: unknown)."""
    if cfg.profile != "auto":
        metrics.set_light(cfg.lux or None, profile or "", not hasattr(source, "set_biases"))
        return None
    controller = BiasController(cfg, source, metrics, profile)
    controller.begin()
    return controller


def _open_source(
    cfg: SourceConfig, metrics: EdgeMetrics, sensor: SensorConfig, coarse: bool = False,
) -> tuple[EventSource, Calibration, Any, Any, str | None]:
    """The event source, its calibration, (for a replayed recording) its gaze and IMU track
    loaders, and the bias profile it runs (a recording's from its ``meta.json``; None when not stated).

    ``coarse``: an as-fast-as-possible replay into a step with its own grid (on-change's
    ``replay_grid_us``) hands over the decoder's chunks whole instead of 1 ms slices: its pipeline
    takes one processing step per slice of the grid whatever the chunking, so whole chunks only
    save the per-chunk cost (slicing and re-joining, ring push, window count, metrics); paced
    replays keep 1 ms, the latency's resolution."""
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.io.calibration import load_calibration

    if cfg.kind == "replay":
        # lazy: only the parts this configuration uses load (USB, websockets, numba)
        from darkread.edge.io.recording import open_recording
        from darkread.edge.sources.replay import DEFAULT_SLICE_US, ReplaySource

        if not cfg.path:
            raise ValueError(
                "nothing to read: pass --replay RECORDING, or a --config whose [source] names a "
                "recording (path) or the camera (kind = \"evk4\")"
            )
        recording = open_recording(cfg.path, gaze=cfg.gaze_csv or None, calibration=cfg.calibration or None)
        slice_us = None if coarse and not cfg.speed else DEFAULT_SLICE_US
        source = ReplaySource(recording.raw_path, speed=cfg.speed or None, slice_us=slice_us)
        calibrated = (recording.calibration.width, recording.calibration.height)
        if calibrated != (source.width, source.height):
            logger.warning("%s: calibration is for %dx%d but the RAW header says %dx%d: gaze lands in the wrong place",
                           cfg.path, *calibrated, source.width, source.height)
        n_events = recording.meta.get("event_count")
        if isinstance(n_events, int) and n_events > 0:  # the bandwidth ratio against this very stream
            metrics.raw_bytes_per_event = recording.raw_path.stat().st_size / n_events
        stated = recording.meta.get("biases")
        profile = profile_named(stated.get("offsets") if isinstance(stated, dict) else None)
        if sensor.profile not in ("auto", profile):
            logger.warning("[sensor] profile %s: a replay cannot change its biases; the recording was made with %s",
                           sensor.profile, profile or "biases it does not state")
        return source, recording.calibration, recording.gaze, recording.imu, profile
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.sources.evk4.camera import Evk4Camera

    if not cfg.calibration:
        raise ValueError("the camera needs a calibration.json: [source] calibration")
    calibration = load_calibration(cfg.calibration)
    profile = FACTORY if sensor.profile == "auto" else sensor.profile  # auto starts at factory and switches
    camera = Evk4Camera(serial=cfg.serial or None, biases=profile_offsets(profile))
    camera.open()
    return camera, calibration, None, None, profile


def _open_imu(cfg: ImuConfig, calibration: Calibration, imu_track: Any, feeds: list[Any]) -> Any:
    """The gyroscope's head motion (``ImuHeadMotion``), or None where there is none; a live feed is
    appended to ``feeds`` (started and stopped with the edge)."""
    if cfg.kind == "none" or (cfg.kind == "recording" and imu_track is None):
        return None
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.imu_motion import ImuHeadMotion
    from darkread.edge.io.imu_csv import read_imu_csv
    from darkread.edge.sources.imu_feed import AriaGen2ImuFeed, UdpImuFeed

    if cfg.kind in ("recording", "csv"):
        track = imu_track() if cfg.kind == "recording" else read_imu_csv(cfg.path)
        if track is None:
            return None
        logger.info("head motion from the gyroscope: %d samples at %.0f Hz", len(track), track.rate_hz)
        return ImuHeadMotion.of_track(track, calibration, clock_offset_us=cfg.clock_offset_us)
    motion = ImuHeadMotion(calibration, clock_offset_us=cfg.clock_offset_us, live=True)
    feeds.append(UdpImuFeed(motion, cfg.udp_host, cfg.udp_port) if cfg.kind == "udp" else AriaGen2ImuFeed(motion))
    return motion


def _open_gaze(cfg: GazeConfig, calibration: Calibration, gaze_track: Any, feeds: list[Any]) -> GazeLookup:
    """The gaze lookup; a live feed is appended to ``feeds`` (started and stopped with the edge)."""
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.gaze import GazeMapper
    from darkread.edge.sources.gaze_feeds import AriaGen2GazeFeed, LiveGaze, UdpGazeFeed, csv_gaze

    if cfg.kind == "recording":
        if gaze_track is None:
            raise ValueError("[gaze] kind 'recording' needs a replayed recording; use csv, udp or aria")
        return GazeMapper(calibration, gaze_track(), clock_offset_us=cfg.clock_offset_us, depth_prior_m=cfg.depth_prior_m)
    if cfg.kind == "csv":
        if not cfg.path:
            raise ValueError("[gaze] kind 'csv' needs [gaze] path")
        return csv_gaze(cfg.path, calibration, clock_offset_us=cfg.clock_offset_us, depth_prior_m=cfg.depth_prior_m)
    live = LiveGaze(
        calibration, clock_offset_us=cfg.clock_offset_us, max_age_us=int(cfg.max_age_ms * 1000),
        depth_prior_m=cfg.depth_prior_m,
    )
    feeds.append(UdpGazeFeed(live, cfg.udp_host, cfg.udp_port) if cfg.kind == "udp" else AriaGen2GazeFeed(live))
    return live


def _open_uplink(config: EdgeConfig, metrics: EdgeMetrics, sensor_wh: tuple[int, int], fovea_hw: tuple[int, int]) -> Any:
    # lazy: only the parts this configuration uses load (USB, websockets, numba)
    from darkread.edge.spool import Spool, spool_directory
    from darkread.edge.uplink import Uplink

    cfg = config.uplink
    spool = Spool(spool_directory(cfg.spool_dir), max_bytes=int(cfg.spool_max_mb * 1024 * 1024))
    try:
        return Uplink(cfg, spool, metrics, sensor_wh=sensor_wh, fovea_hw=fovea_hw)
    except BaseException:  # e.g. a full disk refusing the session's record: free the spool's directory
        spool.close()
        raise
