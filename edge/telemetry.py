"""Edge metrics: counters, rates and latency percentiles, logged and served as Prometheus text.

The hot paths only add to counters and append to bounded reservoirs (``deque(maxlen=...)``), so
memory stays flat. The HTTP endpoint is a tiny stdlib server: prometheus-client is not needed on
the glasses for a dozen gauges.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

logger = logging.getLogger(__name__)

RESERVOIR = 4096
RAW_EVT3_BYTES_PER_EVENT = 2.0  # EVT3 lower bound (one 16-bit word per event); replays measure their own
RGB_FRAME_BYTES_ESTIMATE = 2880 * 2880 * 3 // 2  # a 2880x2880 RGB capture as PNG, about 1.5 bytes/pixel

COUNTERS = (
    "events_in",
    "events_foveated",
    "frames",  # inferences: frames made
    "frames_deblurred",  # frames whose events were moved back along the head's motion (edge.deblur)
    "frames_denoised",  # frames whose isolated events (dim-light shot noise) were dropped (edge.denoise)
    "frames_imu_motion",  # frames whose scene offset came from the gyroscope (edge.imu_motion)
    "frames_imu_fallback",  # ... and those where its stream had a gap: the event tracker's (or unknown)
    "views",  # on-change mode: fused views of fixations
    "views_split",  # on-change mode: views ended early by a frame that did not register onto them
    "frames_gyro_placed",  # on-change mode: dim frames joined to their view where the gyroscope agreed (edge.view_fusion)
    "event_us",  # event-clock time covered by the events read (reading time)
    "frames_skipped",  # windows never inferred because inference fell behind (live): what a busy edge loses
    "frames_no_gaze",
    "events_overwritten",  # ring history overwritten by newer events: normal once the ring is full, no loss
    "shed_changes",  # live: the shedding level changed (edge.load; the level is a gauge)
    "views_capped",  # live, shedding: views denied a frame the view trigger wanted
    "views_shed",  # live, shedding: fixations given no view, the last view covering their window
    "roi_writes",  # the sensor's ROI moved (or given back to the whole sensor): register writes (edge.roi)
    "messages_sent",
    "bytes_sent",
    "messages_acked",
    "messages_rejected",
    "reconnects",
    "failovers",
    "ack_timeouts",
    "pages",
    "bias_switches",  # the sensor's bias profile changed (or, advisory on a replay, would have: edge.bias_control)
)


@dataclass(frozen=True)
class Snapshot:
    """Rates over the interval since the previous snapshot, totals since start."""

    interval_s: float
    totals: dict[str, int]
    rates: dict[str, float]
    inference_ms_p50: float
    inference_ms_p99: float
    latency_ms_p50: float
    latency_ms_p99: float
    spool_depth: int
    spool_lost: int  # messages the full spool evicted before their ack: the uplink's only loss
    step_lag_ms_p99: float = 0.0  # live: how long a step's oldest data waited (edge.load)
    shed_level: int = 0
    raw_bytes_per_event: float = RAW_EVT3_BYTES_PER_EVENT
    cpu_s: float = 0.0  # process CPU time over the interval
    light_lux: float | None = None  # the light at the page, as last estimated (or configured); None: not yet
    bias_profile: str = ""  # the sensor's bias profile ("" when it has none: a replay without one stated)
    bias_advisory: bool = False  # bias_profile is what a replay would run, not what it runs

    @property
    def cpu_per_reading_s(self) -> float:
        """CPU seconds the process spent per second of reading (event time): 1/20 is 20x real time."""
        reading_s = (self.rates["event_us"] * self.interval_s) / 1e6
        return self.cpu_s / reading_s if reading_s > 0 else 0.0

    def status_line(self) -> str:
        """The daemon's ``STATUS=``: what the glasses do for the wearer and what it costs."""
        r = self.rates
        return (
            f"{r['views']:.1f} views/s, {r['frames']:.1f} inferences/s, "
            f"CPU {self.cpu_per_reading_s:.3f} s per reading s, {r['bytes_sent'] / 1e3:.1f} kB/s"
        )

    def log_line(self) -> str:
        r = self.rates
        return (
            f"events {r['events_in']/1e3:.1f}k/s fovea {r['events_foveated']/1e3:.1f}k/s "
            f"views {r['views']:.1f}/s inferences {r['frames']:.1f}/s "
            f"CPU {self.cpu_per_reading_s:.3f} s per reading s infer p50 {self.inference_ms_p50:.1f} p99 {self.inference_ms_p99:.1f} ms "
            f"wire p50 {self.latency_ms_p50:.1f} p99 {self.latency_ms_p99:.1f} ms "
            f"deblurred {self.totals['frames_deblurred']} denoised {self.totals['frames_denoised']} "
            f"skips {self.totals['frames_skipped']} no-gaze {self.totals['frames_no_gaze']} "
            f"roi writes {r['roi_writes']:.1f}/s step lag p99 {self.step_lag_ms_p99:.0f} ms "
            f"shedding level {self.shed_level} (views capped {self.totals['views_capped']}, shed {self.totals['views_shed']}) "
            f"spool {self.spool_depth} (lost {self.spool_lost}) {self.light_text()}"
            f"sent {r['bytes_sent']/1e3:.1f} kB/s ({self.bandwidth_vs_raw():.1%} of raw events, "
            f"{self.bandwidth_vs_rgb():.1%} of one RGB frame per second)"
        )

    def light_text(self) -> str:
        """``light 8.1 lux, biases dark`` for the log line ('' before anything is known)."""
        parts = ([f"light {self.light_lux:.3g} lux"] if self.light_lux is not None else []) + (
            [f"biases {self.bias_profile}" + (" (advisory)" if self.bias_advisory else "")] if self.bias_profile else [])
        return ", ".join(parts) + " " if parts else ""

    def bandwidth_vs_rgb(self) -> float:
        return self.rates["bytes_sent"] / RGB_FRAME_BYTES_ESTIMATE

    def bandwidth_vs_raw(self) -> float:
        raw = self.rates["events_in"] * self.raw_bytes_per_event
        return self.rates["bytes_sent"] / raw if raw > 0 else 0.0


def percentile(values: deque[float] | list[float], q: float) -> float:
    return float(np.percentile(np.fromiter(values, float), q)) if values else 0.0


class EdgeMetrics:
    """Thread-safe counters and reservoirs shared by the pipeline and the uplink."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self.totals = dict.fromkeys(COUNTERS, 0)
        self.inference_ms: deque[float] = deque(maxlen=RESERVOIR)
        self.latency_ms: deque[float] = deque(maxlen=RESERVOIR)
        # px between the gyroscope's and the event tracker's scene motion between frames (where both are known)
        self.motion_disagreement_px: deque[float] = deque(maxlen=RESERVOIR)
        self.step_lag_ms: deque[float] = deque(maxlen=RESERVOIR)
        self.shed_level = 0  # set by the pipeline (edge.load)
        self.spool_depth: Callable[[], int] = lambda: 0
        self.spool_lost: Callable[[], int] = lambda: 0
        self.raw_bytes_per_event = RAW_EVT3_BYTES_PER_EVENT  # the raw stream's size, for the bandwidth ratio
        self.light_lux: float | None = None  # set by the bias controller (edge.bias_control)
        self.bias_profile = ""
        self.bias_advisory = False  # the profile is what the controller would run (a replay cannot switch)
        self._started = clock()
        self._last_time = self._started
        self._last_cpu = time.process_time()
        self._last_totals = dict(self.totals)

    def add(self, name: str, n: int = 1) -> None:
        with self._lock:
            self.totals[name] += n

    def set_light(self, lux: float | None, profile: str, advisory: bool) -> None:
        with self._lock:
            self.light_lux, self.bias_profile, self.bias_advisory = lux, profile, advisory

    def observe_inference(self, ms: float) -> None:
        self.inference_ms.append(ms)  # deque.append is atomic

    def observe_latency(self, ms: float) -> None:
        self.latency_ms.append(ms)

    def observe_motion_disagreement(self, px: float) -> None:
        self.motion_disagreement_px.append(px)
    def observe_step_lag(self, ms: float) -> None:
        self.step_lag_ms.append(ms)

    def snapshot(self) -> Snapshot:
        with self._lock:
            now = self._clock()
            totals = dict(self.totals)
            interval = max(now - self._last_time, 1e-9)
            rates = {k: (totals[k] - self._last_totals[k]) / interval for k in COUNTERS}
            self._last_time, self._last_totals = now, totals
            cpu = time.process_time()
            cpu_s, self._last_cpu = cpu - self._last_cpu, cpu
        inference, latency = list(self.inference_ms), list(self.latency_ms)
        return Snapshot(
            interval_s=interval,
            totals=totals,
            rates=rates,
            inference_ms_p50=percentile(inference, 50),
            inference_ms_p99=percentile(inference, 99),
            latency_ms_p50=percentile(latency, 50),
            latency_ms_p99=percentile(latency, 99),
            spool_depth=self.spool_depth(),
            spool_lost=self.spool_lost(),
            step_lag_ms_p99=percentile(list(self.step_lag_ms), 99),
            shed_level=self.shed_level,
            raw_bytes_per_event=self.raw_bytes_per_event,
            cpu_s=cpu_s,
            light_lux=self.light_lux,
            bias_profile=self.bias_profile,
            bias_advisory=self.bias_advisory,
        )

    def prometheus_text(self) -> str:
        """Prometheus exposition format (text 0.0.4): totals as counters, the rest as gauges."""
        with self._lock:
            totals = dict(self.totals)
            uptime = self._clock() - self._started
            light, profile, advisory = self.light_lux, self.bias_profile, self.bias_advisory
        inference, latency = list(self.inference_ms), list(self.latency_ms)
        disagreement = list(self.motion_disagreement_px)
        lines: list[str] = []

        def metric(name: str, kind: str, help_text: str, samples: list[tuple[str, float]]) -> None:
            lines.append(f"# HELP darkread_edge_{name} {help_text}")
            lines.append(f"# TYPE darkread_edge_{name} {kind}")
            lines.extend(f"darkread_edge_{name}{labels} {value:.6g}" for labels, value in samples)

        for key in COUNTERS:
            metric(f"{key}_total", "counter", key.replace("_", " "), [("", totals[key])])
        for name, values in (("inference_ms", inference), ("event_to_wire_ms", latency)):
            quantiles = [(f'{{quantile="{q}"}}', percentile(values, q * 100)) for q in (0.5, 0.99)]
            metric(name, "gauge", f"{name.replace('_', ' ')} over the last {RESERVOIR} frames", quantiles)
        if disagreement:
            metric("head_motion_disagreement_px", "gauge",
                   "gyroscope vs event tracker: px between their scene motions from frame to frame",
                   [(f'{{quantile="{q}"}}', percentile(disagreement, q * 100)) for q in (0.5, 0.9)])
        metric("spool_depth", "gauge", "messages waiting for an ack", [("", self.spool_depth())])
        metric("shed_level", "gauge", "live and falling behind: 0 none, 1 a view's frames capped at two, 2 at one, 3 at one and "
               "no view where the last covers the window",
               [("", self.shed_level)])
        metric("step_lag_ms", "gauge", f"how long a live step's oldest data waited, over the last {RESERVOIR} steps",
               [(f'{{quantile="{q}"}}', percentile(list(self.step_lag_ms), q * 100)) for q in (0.5, 0.99)])
        metric("spool_lost", "gauge", "messages the full spool evicted before their ack (lost)", [("", self.spool_lost())])
        reading_s = totals["event_us"] / 1e6
        metric("cpu_seconds_per_reading_second", "gauge", "process CPU time per second of event time since start",
               [("", time.process_time() / reading_s if reading_s > 0 else 0.0)])
        metric("uptime_seconds", "gauge", "seconds since start", [("", uptime)])
        if light is not None:
            metric("light_lux", "gauge", "the light at the page as last estimated from the events (or configured)", [("", light)])
        if profile:
            mode = "advisory" if advisory else "applied"
            metric("bias_profile", "gauge", "the sensor's bias profile (1 on the current one; advisory: what a replay would run)",
                   [(f'{{profile="{name}",mode="{mode}"}}', float(name == profile)) for name in sorted({"factory", "dark", profile})])
        return "\n".join(lines) + "\n"


class MetricsServer:
    """``GET /metrics`` on a local port, served from a daemon thread."""

    def __init__(self, metrics: EdgeMetrics, host: str = "127.0.0.1", port: int = 0) -> None:
        metrics_ref = metrics

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # http.server naming
                if self.path.rstrip("/") != "/metrics":
                    self.send_error(404, "try /metrics")
                    return
                body = metrics_ref.prometheus_text().encode()
                self.send_response(200)
                self.send_header("Content-Type", "text/plain; version=0.0.4; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, format: str, *args: object) -> None:  # scrapes stay out of the journal
                pass

        self._server = ThreadingHTTPServer((host, port), Handler)
        self._server.daemon_threads = True
        self.port = int(self._server.server_address[1])
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.1}, name="edge-metrics", daemon=True
        )

    def start(self) -> None:
        self._thread.start()
        logger.info("metrics at http://%s:%d/metrics", self._server.server_address[0], self.port)

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
