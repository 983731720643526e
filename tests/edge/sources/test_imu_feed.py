"""The gyroscope's live feed: datagrams through a real UDP socket on 127.0.0.1 into the head motion."""

from __future__ import annotations

import json
import socket
import time

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from darkread.edge.errors import DeviceError
from darkread.edge.imu_motion import ImuHeadMotion
from darkread.edge.io.calibration import Calibration
from darkread.edge.sources.imu_feed import AriaGen2ImuFeed, UdpImuFeed, parse_imu_datagram


def calibration() -> Calibration:
    return Calibration(width=1280, height=720, fx=600.0, fy=600.0, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
                       T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=0)


def _wait(condition, seconds: float = 2.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_udp_feed_receives_batches_and_counts_rejects() -> None:
    motion = ImuHeadMotion(calibration(), live=True)
    feed = UdpImuFeed(motion, port=0)
    feed.start()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(json.dumps({"clock_offset_us": 1000}).encode(), ("127.0.0.1", feed.port))
            _wait(lambda: motion.clock_offset_us == 1000)
            for k in range(0, 800, 20):  # 0.8 s at 1 kHz, 20 samples a datagram, turning at 0.1 rad/s about CPF y
                batch = [[1_000_000 + 1000 * i, 0.0, 0.1, 0.0] for i in range(k, k + 20)]
                data = msgpack.packb({"imu": batch}) if k % 40 else json.dumps({"imu": batch}).encode()
                sender.sendto(data, ("127.0.0.1", feed.port))
            sender.sendto(b"garbage", ("127.0.0.1", feed.port))
            sender.sendto(json.dumps({"imu": [[1, 0.0, "fast", 0.0]]}).encode(), ("127.0.0.1", feed.port))
            sender.sendto(json.dumps({"imu": [[2, 0.0, 90.0, 0.0]]}).encode(), ("127.0.0.1", feed.port))
        _wait(lambda: motion.received >= 800 and feed.rejected >= 3)
    finally:
        feed.stop()
    assert feed.stats == {"imu_received": 800.0, "imu_rejected": 3.0}
    assert motion.span_us == (1_001_000, 1_800_000)  # on the event clock
    assert not motion.healthy(1_300_000)  # (too little yet to tell whether the head walks)
    assert motion.healthy(1_700_000) and not motion.healthy(1_900_000)  # (held max_age_us after the newest)
    a, b = motion.scene_px(1_600_000), motion.scene_px(1_700_000)
    assert a is not None and b is not None
    assert b[0] - a[0] == pytest.approx(600.0 * 0.1 * 0.1, rel=0.02)  # the camera pans left: the page moves right


def test_udp_port_in_use_is_a_device_error() -> None:
    motion = ImuHeadMotion(calibration(), live=True)
    first = UdpImuFeed(motion, port=0)
    try:
        with pytest.raises(DeviceError, match="IMU on udp"):
            UdpImuFeed(motion, port=first.port)
    finally:
        first.stop()


def test_aria_without_sdk_says_what_to_do() -> None:
    try:
        import aria.stream_receiver  # noqa: F401  # imported only to learn whether it is installed
    except ImportError:
        with pytest.raises(DeviceError, match="imu"):
            AriaGen2ImuFeed(ImuHeadMotion(calibration(), live=True))
    else:  # pragma: no cover
        pytest.skip("the Aria SDK is installed")


samples = st.lists(st.tuples(st.integers(-(2**62), 2**62), *[st.floats(-35.0, 35.0, allow_nan=False)] * 3),
                   min_size=1, max_size=64)


@given(samples, st.booleans())
def test_datagram_codec_round_trips(batch: list[tuple[int, float, float, float]], as_json: bool) -> None:
    payload = {"imu": [list(sample) for sample in batch]}
    data = json.dumps(payload).encode() if as_json else msgpack.packb(payload)
    if len(data) > 1024:
        with pytest.raises(ValueError, match="exceeds"):
            parse_imu_datagram(data)
        return
    t, omega = parse_imu_datagram(data)
    assert t.tolist() == [s[0] for s in batch] and omega.tolist() == [list(s[1:]) for s in batch]
