"""Prometheus metrics of one app instance (its own registry, so several apps can coexist in tests)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram


class Metrics:
    """Websocket ingest counters plus OCR timings; exposed at ``/metrics``."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.connections = Counter("darkread_ws_connections", "Websocket connections accepted", registry=r)
        self.denied = Counter("darkread_ws_denied", "Websocket handshakes denied (bad API key)", registry=r)
        self.active = Gauge("darkread_ws_active_connections", "Websocket connections open now", registry=r)
        self.messages = Counter(
            "darkread_ws_messages", "Messages received, by type", ["type"], registry=r
        )
        self.bytes_received = Counter("darkread_ws_received_bytes", "Bytes of messages received", registry=r)
        self.frames_stored = Counter("darkread_ws_frames_stored", "Frames durably stored", registry=r)
        self.pages_stored = Counter("darkread_ws_pages_stored", "Pages durably stored", registry=r)
        self.views_shed = Counter(
            "darkread_ws_views_shed", "Views stored that the glasses made while shedding work to keep up (edge.load), by level",
            ["level"], registry=r,
        )
        self.duplicates = Counter("darkread_ws_duplicates", "Messages dropped as duplicates (re-acked)", registry=r)
        self.errors = Counter("darkread_ws_errors", "Stream errors, by close code", ["code"], registry=r)
        self.store_failures = Counter(
            "darkread_ws_store_failures", "Messages whose store path failed (connection closed), by error", ["error"],
            registry=r,
        )
        self.ocr_seconds = Histogram(
            "darkread_ocr_seconds",
            "OCR time per request",
            ["backend"],
            buckets=(0.05, 0.1, 0.25, 0.5, 1, 2, 5, 10, 30, 60),
            registry=r,
        )
        self.ask_errors = Counter("darkread_ask_errors", "Ask requests that failed, by reason", ["reason"], registry=r)
