"""Gaze sources: MPS CSV replay, a UDP datagram feed for any eye tracker, Aria Gen2 live gaze.

All of them answer the pipeline's one question, ``at(t_event_us) -> GazeSample | None``, on the
**event clock**. Gaze arrives on its own device clock;
``clock_offset_us`` (``t_event = t_device + offset``, from ``calibration.json``) maps it and can
be changed while running (e.g. after re-synchronising the clocks).

UDP datagram (one sample per datagram, JSON object or msgpack map, UTF-8, <= 1 KiB)::

    {"t_us": 123456789, "yaw": 0.05, "pitch": -0.10, "depth_m": 0.42}

``t_us`` integer microseconds on the tracker's device clock; ``yaw`` and ``pitch`` radians in CPF,
projection convention (direction proportional to (tan yaw, tan pitch, 1), x to the wearer's left,
y up); ``depth_m`` optional metres to the gaze point (absent or null: the reading-depth prior).
Invalid datagrams are counted and ignored.

A control datagram ``{"clock_offset_us": -1234}`` (integer) sets the gaze -> event clock offset
while running, e.g. after the tracker re-synchronised its clock.
"""

from __future__ import annotations

import bisect
import json
import logging
import math
import socket
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from darkread.edge.errors import DeviceError
from darkread.edge.gaze import READING_DEPTH_PRIOR_M, GazeMapper, GazeSample, gaze_sample
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.gaze_csv import read_gaze_csv

logger = logging.getLogger(__name__)

MAX_DATAGRAM_BYTES = 1024
ARIA_SDK_HINT = (
    "live Aria Gen2 gaze needs the Project Aria client SDK: `pip install projectaria-client-sdk` "
    "(Python 3.10-3.12, x86_64 or aarch64); or stream gaze to the UDP feed instead (--gaze udp)"
)


def csv_gaze(path: str | Path, calibration: Calibration, *, clock_offset_us: int | None = None,
             depth_prior_m: float = READING_DEPTH_PRIOR_M) -> GazeMapper:
    """MPS ``general_eye_gaze.csv`` replay: the whole track is known, so interpolate exactly."""
    return GazeMapper(calibration, read_gaze_csv(path), clock_offset_us=clock_offset_us, depth_prior_m=depth_prior_m)


class LiveGaze:
    """The newest gaze samples of a live feed (bounded), looked up on the event clock.

    Between two samples the angles are interpolated; after the newest sample it is held for
    ``max_age_us``; older than that (or before the first sample) there is no gaze. Samples live in
    plain lists searched by bisection, trimmed in batches, so a lookup copies nothing.
    """

    def __init__(
        self,
        calibration: Calibration,
        *,
        clock_offset_us: int | None = None,
        max_age_us: int = 100_000,
        depth_prior_m: float = READING_DEPTH_PRIOR_M,
        capacity: int = 256,
    ) -> None:
        self.calibration = calibration
        self.clock_offset_us = int(calibration.gaze_to_event_time_offset_us if clock_offset_us is None else clock_offset_us)
        self.max_age_us = int(max_age_us)
        self.depth_prior_m = float(depth_prior_m)
        self.capacity = int(capacity)
        self._times: list[int] = []  # device clock, increasing
        self._values: list[tuple[float, float, float]] = []  # (yaw, pitch, depth)
        self._lock = threading.Lock()
        self.received = 0

    def push(self, t_device_us: int, yaw_rad: float, pitch_rad: float, depth_m: float | None = None) -> None:
        depth = depth_m if depth_m is not None and math.isfinite(depth_m) and depth_m > 0 else self.depth_prior_m
        with self._lock:
            if self._times and t_device_us <= self._times[-1]:
                return  # out of order or repeated: keep the track monotonic
            self._times.append(int(t_device_us))
            self._values.append((float(yaw_rad), float(pitch_rad), float(depth)))
            if len(self._times) > 2 * self.capacity:  # amortised: one trim per ``capacity`` pushes
                del self._times[: -self.capacity], self._values[: -self.capacity]
            self.received += 1

    def _interpolate(self, t_event_us: int) -> tuple[float, float, float] | None:
        """(yaw, pitch, depth) at an event time, or None outside the held track."""
        t = int(t_event_us) - self.clock_offset_us
        with self._lock:
            times, values = self._times, self._values
            if not times or t < times[0] or t > times[-1] + self.max_age_us:
                return None
            if t >= times[-1]:
                return values[-1]
            right = bisect.bisect_right(times, t)  # times[right - 1] <= t < times[right]
            t0, t1 = times[right - 1], times[right]
            v0, v1 = values[right - 1], values[right]
        w = (t - t0) / (t1 - t0)
        return v0[0] + w * (v1[0] - v0[0]), v0[1] + w * (v1[1] - v0[1]), v0[2] + w * (v1[2] - v0[2])

    @property
    def rate_hz(self) -> float:
        """The feed's row rate, from the rows held (Aria: 10 to 90 Hz); 60 until two arrived."""
        with self._lock:
            times = self._times[-64:]
        if len(times) < 2:
            return 60.0
        period = float(np.median(np.diff(times)))
        return 1e6 / period if period > 0 else 60.0

    def rows(self, t0_event_us: int, t1_event_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The held rows with event time in (t0, t1]: (t_event_us, yaw, pitch)."""
        lo, hi = int(t0_event_us) - self.clock_offset_us, int(t1_event_us) - self.clock_offset_us
        with self._lock:
            i0 = bisect.bisect_right(self._times, lo)
            i1 = bisect.bisect_right(self._times, hi)
            times, values = self._times[i0:i1], self._values[i0:i1]
        t = np.asarray(times, dtype=np.int64) + self.clock_offset_us
        angles = np.asarray(values, dtype=np.float64).reshape(-1, 3)
        return t, angles[:, 0], angles[:, 1]

    def at(self, t_event_us: int) -> GazeSample | None:
        value = self._interpolate(t_event_us)
        return None if value is None else gaze_sample(self.calibration, *value)


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def parse_gaze_datagram(data: bytes) -> tuple[int, float, float, float | None]:
    """One UDP datagram (JSON object or msgpack map) -> (t_us, yaw, pitch, depth_m or None)."""
    return _gaze_sample(datagram_payload(data))


def datagram_payload(data: bytes) -> Mapping[str, Any]:
    """A datagram's JSON object or msgpack map (the gaze's and the IMU's feeds alike); ValueError if neither."""
    if len(data) > MAX_DATAGRAM_BYTES:
        raise ValueError(f"datagram of {len(data)} bytes exceeds {MAX_DATAGRAM_BYTES}")
    try:
        if data[:1] in (b"{", b" ", b"\n"):
            payload = json.loads(data.decode("utf-8"))
        else:
            payload = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except (ValueError, UnicodeDecodeError, msgpack.UnpackException) as exc:
        raise ValueError(f"not JSON or msgpack: {exc}") from None
    if not isinstance(payload, Mapping):
        raise ValueError("a gaze datagram must be a JSON object or msgpack map")
    return payload


def _gaze_sample(payload: Mapping[str, Any]) -> tuple[int, float, float, float | None]:
    t_us = payload.get("t_us")
    if isinstance(t_us, bool) or not isinstance(t_us, int):
        raise ValueError(f"t_us must be an integer (microseconds), got {t_us!r}")
    yaw = _finite(payload.get("yaw"), "yaw")
    pitch = _finite(payload.get("pitch"), "pitch")
    depth = payload.get("depth_m")
    return t_us, yaw, pitch, None if depth is None else _finite(depth, "depth_m")


class UdpFeed:
    """A UDP port whose datagrams (JSON objects or msgpack maps) feed a live stream, on its own
    thread: the gaze's, the gyroscope's. A datagram with ``clock_offset_us`` and no sample sets the
    stream's clock offset; every other one is handed to ``_accept``. A bad one is counted in
    ``rejected`` (its reason logged at debug level), never fatal."""

    what = "datagrams"  # what the port carries, for messages
    sample_key = "t_us"  # a datagram with this key is a sample, even with a clock offset beside it

    def __init__(self, host: str, port: int) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise DeviceError(f"cannot listen for {self.what} on udp://{host}:{port}: {exc}") from exc
        self._sock.settimeout(0.2)
        self.port = int(self._sock.getsockname()[1])
        self.rejected = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"{self.what.lower()}-udp", daemon=True)

    def start(self) -> None:
        self._thread.start()
        logger.info("%s feed listening on udp port %d", self.what, self.port)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._sock.close()

    def _accept(self, payload: Mapping[str, Any]) -> None:
        """One sample datagram's payload into the stream (ValueError: rejected)."""
        raise NotImplementedError

    def _set_clock_offset(self, value: int) -> None:
        raise NotImplementedError

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._sock.recv(MAX_DATAGRAM_BYTES + 1)
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                payload = datagram_payload(data)
                if "clock_offset_us" in payload and self.sample_key not in payload:
                    value = payload["clock_offset_us"]
                    if isinstance(value, bool) or not isinstance(value, int):
                        raise ValueError(f"clock_offset_us must be an integer, got {value!r}")
                    self._set_clock_offset(value)
                else:
                    self._accept(payload)
            except ValueError as exc:
                self.rejected += 1
                if logger.isEnabledFor(logging.DEBUG):
                    logger.debug("%s datagram rejected: %s", self.what, exc)


class UdpGazeFeed(UdpFeed):
    """Receives gaze datagrams on a UDP port into a :class:`LiveGaze` (its own thread)."""

    what = "gaze"

    def __init__(self, live: LiveGaze, host: str = "127.0.0.1", port: int = 7007) -> None:
        self.live = live
        super().__init__(host, port)

    @property
    def stats(self) -> dict[str, float]:
        return {"gaze_received": float(self.live.received), "gaze_rejected": float(self.rejected)}

    def _set_clock_offset(self, value: int) -> None:
        logger.info("gaze clock offset %d -> %d us", self.live.clock_offset_us, value)
        self.live.clock_offset_us = value

    def _accept(self, payload: Mapping[str, Any]) -> None:
        self.live.push(*_gaze_sample(payload))


class AriaGen2GazeFeed:
    """Live gaze from Aria Gen2 glasses through the client SDK's stream receiver (optional).

    The SDK's eye-gaze callback delivers ``EyeGaze`` records (yaw, pitch, depth, device time);
    they go into the same :class:`LiveGaze` as the UDP feed. Written against the client SDK 2.x
    stream receiver (host server on port 6768); not exercised without glasses, so an SDK whose
    API differs is reported as a ``DeviceError`` naming the mismatch.
    """

    def __init__(self, live: LiveGaze, port: int = 6768) -> None:
        try:
            from aria import stream_receiver
        except ImportError as exc:
            raise DeviceError(ARIA_SDK_HINT) from exc
        self.live = live
        try:  # pragma: no cover (needs the SDK)
            self._receiver = stream_receiver.StreamReceiver(server_port=port)
            self._receiver.register_eye_gaze_callback(self._on_gaze)
        except (AttributeError, TypeError) as exc:  # pragma: no cover
            raise DeviceError(
                f"this projectaria-client-sdk has no usable stream receiver ({exc}); "
                "stream gaze to the UDP feed instead (--gaze udp)"
            ) from exc

    def _on_gaze(self, gaze: Any) -> None:  # pragma: no cover (hardware)
        t_us = int(gaze.tracking_timestamp.total_seconds() * 1e6)
        depth = getattr(gaze, "depth", None)
        self.live.push(t_us, float(gaze.yaw), float(gaze.pitch), float(depth) if depth else None)

    def start(self) -> None:  # pragma: no cover (hardware)
        self._receiver.start_server()

    def stop(self) -> None:  # pragma: no cover (hardware)
        stop = getattr(self._receiver, "stop_server", None)
        if stop is not None:
            stop()
