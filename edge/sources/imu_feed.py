"""The gyroscope live, beside the live gaze (``edge.sources.gaze_feeds``): UDP datagrams into an
``ImuHeadMotion``, or Aria Gen2's IMU through the client SDK.

UDP datagram (JSON object or msgpack map, <= 1 KiB, as the gaze feed's), a batch of samples::

    {"imu": [[t_us, wx, wy, wz], ...]}

``t_us`` integer microseconds on the device clock (the gaze's: ``calibration.json``'s offset maps
both to the event clock); ``wx, wy, wz`` the angular velocity in rad/s in the device frame (CPF:
x to the wearer's left, y up, z forward), as the recording format's ``closed_loop_trajectory.csv``
(``edge.io.imu_csv``). At 1 kHz a datagram of 20 samples (about 560 bytes of JSON) every 20 ms.
Samples are appended in time order; older ones than those held are ignored; invalid datagrams are
counted and ignored. A control datagram ``{"clock_offset_us": -1234}`` sets the clock offset.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from darkread.edge.errors import DeviceError
from darkread.edge.imu_motion import ImuHeadMotion
from darkread.edge.io.imu_csv import MAX_ANGULAR_SPEED_RAD_S
from darkread.edge.sources.gaze_feeds import ARIA_SDK_HINT, UdpFeed, datagram_payload

logger = logging.getLogger(__name__)

MAX_SAMPLES_PER_DATAGRAM = 64


def imu_samples(payload: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """A datagram's ``imu`` batch -> (t_us int64 [n], omega float64 [n, 3]); ValueError says what is wrong."""
    batch = payload.get("imu")
    if not isinstance(batch, list) or not 0 < len(batch) <= MAX_SAMPLES_PER_DATAGRAM:
        raise ValueError(f"imu must be a list of 1 to {MAX_SAMPLES_PER_DATAGRAM} samples [t_us, wx, wy, wz]")
    t_us = np.empty(len(batch), np.int64)
    omega = np.empty((len(batch), 3), np.float64)
    for i, sample in enumerate(batch):  # (at most 64 a datagram)
        if not isinstance(sample, list) or len(sample) != 4:
            raise ValueError(f"sample {i}: expected [t_us, wx, wy, wz], got {sample!r}")
        t, *w = sample
        if isinstance(t, bool) or not isinstance(t, int):
            raise ValueError(f"sample {i}: t_us must be an integer (microseconds), got {t!r}")
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > MAX_ANGULAR_SPEED_RAD_S
               for v in w):
            raise ValueError(f"sample {i}: angular velocity must be finite numbers within "
                             f"{MAX_ANGULAR_SPEED_RAD_S:g} rad/s, got {w!r}")
        t_us[i], omega[i] = t, w
    return t_us, omega


def parse_imu_datagram(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """One UDP datagram (JSON object or msgpack map) -> (t_us [n], omega [n, 3])."""
    return imu_samples(datagram_payload(data))


class UdpImuFeed(UdpFeed):
    """Receives gyroscope datagrams on a UDP port into an :class:`ImuHeadMotion` (its own thread)."""

    what = "IMU"
    sample_key = "imu"

    def __init__(self, motion: ImuHeadMotion, host: str = "127.0.0.1", port: int = 7008) -> None:
        self.motion = motion
        super().__init__(host, port)

    @property
    def stats(self) -> dict[str, float]:
        return {"imu_received": float(self.motion.received), "imu_rejected": float(self.rejected)}

    def _set_clock_offset(self, value: int) -> None:
        self.motion.clock_offset_us = value

    def _accept(self, payload: Mapping[str, Any]) -> None:
        self.motion.extend(*imu_samples(payload))


class AriaGen2ImuFeed:
    """Aria Gen2's IMU through the client SDK's stream receiver (optional; as ``AriaGen2GazeFeed``).

    The SDK's IMU callback delivers motion data (device time, gyroscope rad/s in the IMU's frame);
    ``R_device_imu`` (the glasses' factory calibration, IMU into CPF axes) rotates them into the
    recording format's device frame. Not exercised without glasses: an SDK whose API differs is a
    ``DeviceError`` naming the mismatch.
    """

    def __init__(self, motion: ImuHeadMotion, R_cpf_imu: np.ndarray | None = None, port: int = 6768) -> None:
        try:
            from aria import stream_receiver
        except ImportError as exc:
            raise DeviceError(ARIA_SDK_HINT.replace("gaze", "IMU").replace("--IMU udp", "[imu] kind = \"udp\"")) from exc
        self.motion = motion
        self._R = np.eye(3) if R_cpf_imu is None else np.asarray(R_cpf_imu, np.float64)
        try:  # pragma: no cover (needs the SDK)
            self._receiver = stream_receiver.StreamReceiver(server_port=port)
            self._receiver.register_imu_callback(self._on_imu)
        except (AttributeError, TypeError) as exc:  # pragma: no cover
            raise DeviceError(f"this projectaria-client-sdk has no usable IMU stream ({exc}); "
                              "stream the gyroscope to the UDP feed instead ([imu] kind = \"udp\")") from exc

    def _on_imu(self, samples: Any, *_: Any) -> None:  # pragma: no cover (hardware)
        t = np.array([int(s.capture_timestamp_ns) // 1000 for s in samples], np.int64)
        w = np.array([list(s.gyro_radsec) for s in samples], np.float64) @ self._R.T
        self.motion.extend(t, w)

    def start(self) -> None:  # pragma: no cover (hardware)
        self._receiver.start_server()

    def stop(self) -> None:  # pragma: no cover (hardware)
        stop = getattr(self._receiver, "stop_server", None)
        if stop is not None:
            stop()
