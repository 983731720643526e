"""Lifecycle of the edge process: signals, systemd notify/watchdog, graceful shutdown.

Modelled on uvicorn's ``Server``: one object owns startup, a 0.1 s tick loop for periodic duties
(status line, metrics log) and a bounded graceful shutdown. ``READY=1`` is sent only once the
sensor is open and the model is warm; ``WATCHDOG=1`` is sent from the processing loop itself (the
pipeline calls :meth:`Notifier.watchdog_tick`), so a stalled pipeline misses pings and systemd
restarts it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from types import FrameType
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from darkread.edge.config import EdgeConfig

logger = logging.getLogger(__name__)


class JournalFormatter(logging.Formatter):
    """``<priority>name: message`` lines: journald reads the syslog priority, adds time and unit."""

    PRIORITIES = ((logging.CRITICAL, 2), (logging.ERROR, 3), (logging.WARNING, 4), (logging.INFO, 6))

    def format(self, record: logging.LogRecord) -> str:
        priority = next((p for level, p in self.PRIORITIES if record.levelno >= level), 7)
        text = f"{record.name}: {record.getMessage()}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return "\n".join(f"<{priority}>{line}" for line in text.splitlines())


def use_journal_format_if_under_systemd(environ: Mapping[str, str] | None = None) -> bool:
    """Switch the root handlers to :class:`JournalFormatter` when stderr goes to the journal."""
    if not (os.environ if environ is None else environ).get("JOURNAL_STREAM"):
        return False
    for handler in logging.getLogger().handlers:
        handler.setFormatter(JournalFormatter())
    return True


def sd_notify(state: str, environ: Mapping[str, str] | None = None) -> bool:
    """Send one sd_notify(3) datagram (``READY=1``, ``STATUS=...``); False when not under systemd."""
    address = (os.environ if environ is None else environ).get("NOTIFY_SOCKET", "")
    if not address or address[0] not in "/@":
        return False
    if address[0] == "@":  # abstract namespace socket
        address = "\0" + address[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
            sock.setblocking(False)  # never stall the processing loop on a full notify queue
            sock.connect(address)
            sock.sendall(state.encode("utf-8"))
    except OSError as exc:
        logger.debug("sd_notify(%r) failed: %s", state, exc)
        return False
    return True


class Notifier:
    """systemd state notifications; watchdog pings at half of ``$WATCHDOG_USEC``."""

    def __init__(self, environ: Mapping[str, str] | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self._environ = dict(os.environ if environ is None else environ)
        self._clock = clock
        usec = self._environ.get("WATCHDOG_USEC", "")
        pid = self._environ.get("WATCHDOG_PID", "")
        enabled = usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid()))
        self.watchdog_interval_s: float | None = int(usec) / 2e6 if enabled else None
        self._last_ping = float("-inf")

    def notify(self, state: str) -> bool:
        return sd_notify(state, self._environ)

    def ready(self, status: str = "") -> None:
        self.notify("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def status(self, text: str) -> None:
        self.notify(f"STATUS={text}")

    def stopping(self) -> None:
        self.notify("STOPPING=1")

    def watchdog_tick(self) -> bool:
        """Ping the watchdog when due; call from the loop whose liveness matters."""
        if self.watchdog_interval_s is None:
            return False
        now = self._clock()
        if now - self._last_ping < self.watchdog_interval_s:
            return False
        self._last_ping = now
        return self.notify("WATCHDOG=1")


class Service(Protocol):
    """What the daemon runs: the wired edge application (see ``darkread.edge.cli``)."""

    def startup(self) -> str: ...  # opens the sensor, warms the model; returns a status line
    def tick(self) -> str | None: ...  # periodic duty; returns a status line or None
    def finished(self) -> bool: ...  # e.g. a replay reached its end
    def shutdown(self, timeout_s: float) -> bool: ...  # drain + flush; True when nothing was lost


HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM)
SENT_SEQS_KEPT = 1 << 17


class Daemon:
    """Runs a :class:`Service` until it finishes or a signal asks it to stop."""

    def __init__(
        self,
        service: Service,
        notifier: Notifier | None = None,
        tick_s: float = 0.1,
        status_every_s: float = 5.0,
        shutdown_timeout_s: float = 10.0,
    ) -> None:
        self.service = service
        self.notifier = notifier or Notifier()
        self.tick_s = tick_s
        self.status_every_s = status_every_s
        self.shutdown_timeout_s = shutdown_timeout_s
        self.should_exit = threading.Event()
        self.force_exit = False

    def run(self) -> int:
        with self.capture_signals():
            try:
                status = self.service.startup()
                self.notifier.ready(status)
                logger.info("ready: %s", status)
                last_status = time.monotonic()
                while not self.should_exit.is_set() and not self.service.finished():
                    line = self.service.tick()
                    if line and time.monotonic() - last_status >= self.status_every_s:
                        self.notifier.status(line)
                        last_status = time.monotonic()
                    self.should_exit.wait(self.tick_s)
            finally:  # also on a failure: drain what can be drained, keep the rest spooled
                self.notifier.stopping()
                self.notifier.status("draining")
                clean = self.service.shutdown(0.0 if self.force_exit else self.shutdown_timeout_s)
        logger.info("stopped (%s)", "clean" if clean else "messages left in the spool")
        return 0 if clean else 3

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        if self.should_exit.is_set() and sig == signal.SIGINT:
            self.force_exit = True  # a second Ctrl-C skips the drain
        self.should_exit.set()

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield  # signals can only be handled in the main thread
            return
        original = {sig: signal.signal(sig, self.handle_exit) for sig in HANDLED_SIGNALS}
        try:
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)


# -- the wired edge application ------------------------------------------------------------------


class EdgeService:
    """Source + gaze + reconstructor + pipeline + uplink + metrics, built from an ``EdgeConfig``."""

    def __init__(self, config: EdgeConfig, notifier: Notifier | None = None) -> None:
        from darkread.edge.telemetry import EdgeMetrics

        self.config = config
        self.notifier = notifier or Notifier()
        self.metrics = EdgeMetrics()
        self.sent_seqs: deque[int] = deque(maxlen=SENT_SEQS_KEPT)  # newest seqs handed to the uplink
        self.source: Any = None
        self.pipeline: Any = None
        self.uplink: Any = None
        self._feeds: list[Any] = []
        self._metrics_server: Any = None
        self._pages: Any = None
        self._last_log = time.monotonic()
        self._last_page = time.monotonic()
        self._page_lock = threading.Lock()

    # -- Service -----------------------------------------------------------------------------
    def startup(self) -> str:
        from darkread.edge.fovea import FoveaConfig
        from darkread.edge.telemetry import MetricsServer
        from darkread.edge.pipeline import Pipeline, PipelineSettings
        from darkread.edge.reconstruct import Reconstructor
        from darkread.edge.spool import Spool
        from darkread.edge.uplink import Uplink, UplinkSettings

        cfg = self.config
        calibration, gaze_track = self._open_source()
        gaze = self._open_gaze(calibration, gaze_track)
        from darkread.edge.io.evt3 import warm_up as warm_up_decoder

        warm_up_decoder()  # READY only once the first chunk can be decoded without a JIT pause
        reconstructor = Reconstructor(cfg.pipeline.model or None, threads=cfg.pipeline.threads)
        fovea = FoveaConfig(height=cfg.pipeline.fovea_height, width=cfg.pipeline.fovea_width)
        spool = Spool(cfg.uplink.spool_dir or None, max_bytes=int(cfg.uplink.spool_max_mb * 1024 * 1024))
        self.uplink = Uplink(
            UplinkSettings(
                url=cfg.uplink.url, api_key=cfg.uplink.api_key, device_id=cfg.uplink.device_id,
                session_id=cfg.uplink.session_id, mode=cfg.uplink.mode,
                sensor_wh=(self.source.width, self.source.height), fovea_hw=(fovea.height, fovea.width),
                backoff_initial_s=cfg.uplink.backoff_initial_s, backoff_max_s=cfg.uplink.backoff_max_s,
                max_in_flight=cfg.uplink.max_in_flight,
            ),
            spool,
            self.metrics,
        )
        if cfg.uplink.mode == "pages":
            from darkread.stitch import PageStitcher

            self._pages = PageStitcher()
        settings = PipelineSettings(
            n_events=cfg.pipeline.n_events, period_ms=cfg.pipeline.period_ms, fovea=fovea,
            bins=cfg.pipeline.bins, stall_s=cfg.pipeline.stall_s, sensor_roi=cfg.pipeline.sensor_roi,
            # a replay as fast as possible has no clock to keep up with: make every window
            lossless=cfg.pipeline.lossless or (cfg.source.kind == "replay" and cfg.source.speed == 0),
        )
        self.pipeline = Pipeline(
            self.source, gaze, reconstructor, self._on_frame, settings, self.metrics,
            ring_capacity=cfg.pipeline.ring_capacity, watchdog=self.notifier.watchdog_tick,
        )
        if cfg.metrics.port:
            self._metrics_server = MetricsServer(self.metrics, cfg.metrics.host, cfg.metrics.port)
            self._metrics_server.start()
        self.uplink.start()
        for feed in self._feeds:
            feed.start()
        self.pipeline.start()
        return (
            f"{cfg.source.kind} {self.source.width}x{self.source.height} open, model {reconstructor.path.name} warm, "
            f"sending {cfg.uplink.mode} to {cfg.uplink.url} (session {self.uplink.session_id})"
        )

    def tick(self) -> str | None:
        if self.pipeline.error is not None:
            raise RuntimeError(f"reconstruction loop failed: {self.pipeline.error}") from self.pipeline.error
        if getattr(self.source, "error", None) is not None:
            raise RuntimeError(f"event source failed: {self.source.error}") from self.source.error
        if self._pages is not None and time.monotonic() - self._last_page >= self.config.uplink.page_every_s:
            self._send_page()
        if time.monotonic() - self._last_log < self.config.metrics.log_every_s:
            return None
        self._last_log = time.monotonic()
        snap = self.metrics.snapshot()
        logger.info("%s", snap.log_line())
        state = "connected" if self.uplink.connected.is_set() else f"offline ({self.uplink.last_error or 'connecting'})"
        return f"{snap.rates['frames']:.1f} frames/s, spool {snap.spool_depth}, uplink {state}"

    def finished(self) -> bool:
        finished = getattr(self.source, "finished", None)
        return bool(finished is not None and finished.is_set()) or not self.pipeline.running

    def shutdown(self, timeout_s: float) -> bool:
        if self.pipeline is not None:
            self.pipeline.stop()  # the last frame comes from what is buffered
        for feed in self._feeds:
            feed.stop()
        if self._pages is not None and self.pipeline is not None:
            self._send_page(final=True)
        drained = True
        if self.uplink is not None:
            drained = self.uplink.stop(drain_timeout_s=timeout_s)
            self.uplink.spool.close()
        if self._metrics_server is not None:
            self._metrics_server.stop()
        close = getattr(self.source, "close", None)
        if close is not None:
            close()
        if self.pipeline is not None:
            logger.info("final: %s", self.metrics.snapshot().log_line())
        return drained

    # -- wiring ------------------------------------------------------------------------------
    def _open_source(self) -> tuple[Any, Any]:
        """The event source, its calibration and (for a replayed recording) its gaze track."""
        from darkread.edge.io.calibration import load_calibration

        cfg = self.config.source
        if cfg.kind == "replay":
            from darkread.edge.io.recording import open_recording
            from darkread.edge.sources.replay import ReplaySource

            if not cfg.path:
                raise ValueError(
                    "nothing to read: pass --replay RECORDING, or a --config whose [source] names a "
                    "recording (path) or the camera (kind = \"evk4\")"
                )
            recording = open_recording(cfg.path, gaze=cfg.gaze_csv or None, calibration=cfg.calibration or None)
            self.source = ReplaySource(recording.raw_path, speed=cfg.speed or None)
            n_events = recording.meta.get("event_count")
            if isinstance(n_events, int) and n_events > 0:  # the bandwidth ratio against this very stream
                self.metrics.raw_bytes_per_event = recording.raw_path.stat().st_size / n_events
            return recording.calibration, recording.gaze
        from darkread.edge.sources.evk4.camera import Evk4Camera

        if not cfg.calibration:
            raise ValueError("the camera needs a calibration.json: [source] calibration")
        calibration = load_calibration(cfg.calibration)
        camera = Evk4Camera(serial=cfg.serial or None)
        camera.open()
        self.source = camera
        return calibration, None

    def _open_gaze(self, calibration: Any, gaze_track: Any) -> Any:
        from darkread.edge.gaze import GazeMapper
        from darkread.edge.sources.gaze_feeds import AriaGen2GazeFeed, LiveGaze, UdpGazeFeed, csv_gaze

        cfg = self.config.gaze
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
        self._feeds.append(UdpGazeFeed(live, cfg.udp_host, cfg.udp_port) if cfg.kind == "udp" else AriaGen2GazeFeed(live))
        return live

    def _on_frame(self, frame: Any, arrival: float) -> None:
        if self._pages is None:
            self.sent_seqs.append(self.uplink.submit(frame.to_message(), submitted_at=arrival))
            return
        with self._page_lock:
            self._pages.add(frame)  # a FrameResult is the frame record the stitcher reads

    def _send_page(self, final: bool = False) -> None:
        from darkread.proto.messages import Page, pack_mask

        with self._page_lock:
            if final:
                self._pages.flush()
            page = self._pages.page()
            t_us = self.pipeline.ring.newest_t or 0
        self._last_page = time.monotonic()
        if page.image.size == 0 or not page.image.any():
            return
        shape, bits = pack_mask(page.image)
        message = Page(seq=0, page_id=0, t_us=int(t_us), shape=shape, bits=bits, lines=tuple(tuple(map(int, b)) for b in page.lines))
        self.sent_seqs.append(self.uplink.submit(message))
        self.metrics.add("pages")
