from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
from factories import angles_at, pixel_at

from darkread.edge.errors import DeviceError
from darkread.edge.io.calibration import Calibration, load_calibration
from darkread.edge.sources.gaze_feeds import (
    AriaGen2GazeFeed,
    LiveGaze,
    UdpGazeFeed,
    csv_gaze,
    parse_gaze_datagram,
)


def calibration(offset_us: int = 1_000) -> Calibration:
    # camera looks forward from the CPF origin: CPF x left / y up -> camera x right / y down
    return Calibration(
        width=1280, height=720, fx=600.0, fy=600.0, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
        T_event_cpf=np.diag([-1.0, -1.0, 1.0, 1.0]), gaze_to_event_time_offset_us=offset_us,
    )


def test_live_gaze_projects_and_interpolates_on_the_event_clock() -> None:
    live = LiveGaze(calibration(offset_us=1_000), max_age_us=50_000)
    live.push(0, 0.0, 0.0, 0.5)
    live.push(10_000, 0.2, 0.0, 0.5)
    assert pixel_at(live, 1_000) == pytest.approx((640.0, 360.0))
    yaw, pitch = angles_at(live, 6_000)  # device 5000: halfway
    assert yaw == pytest.approx(0.1) and pitch == 0.0
    u, _ = pixel_at(live, 11_000)
    assert u == pytest.approx(640.0 - 600.0 * np.tan(0.2))  # positive yaw looks to the wearer's left
    assert pixel_at(live, 0) is None  # before the first sample
    assert pixel_at(live, 11_000 + 50_000) is not None  # newest sample held for max_age
    assert pixel_at(live, 11_000 + 50_001) is None  # too old


def test_live_gaze_clock_offset_is_adjustable_at_run_time() -> None:
    live = LiveGaze(calibration(offset_us=0))
    live.push(5_000, 0.0, 0.1)
    assert angles_at(live, 4_000) is None
    live.clock_offset_us = -1_000
    assert angles_at(live, 4_000) == pytest.approx((0.0, 0.1))


def test_live_gaze_off_sensor_or_out_of_order() -> None:
    live = LiveGaze(calibration(offset_us=0))
    live.push(1_000, 1.4, 0.0)  # far to the side: off the sensor
    assert live.received == 1 and live.at(1_000) is None  # held, but its pixel misses the sensor
    live.push(500, 0.0, 0.0)  # older than the newest: ignored
    assert live.received == 1


@pytest.mark.parametrize("encode", [lambda d: json.dumps(d).encode(), msgpack.packb])
def test_parse_datagram_json_and_msgpack(encode) -> None:
    assert parse_gaze_datagram(encode({"t_us": 7, "yaw": 0.1, "pitch": -0.2, "depth_m": 0.4})) == (7, 0.1, -0.2, 0.4)
    assert parse_gaze_datagram(encode({"t_us": 7, "yaw": 0, "pitch": 0})) == (7, 0.0, 0.0, None)


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"not json",
        b"[1, 2]",
        json.dumps({"yaw": 0.1, "pitch": 0.0}).encode(),
        json.dumps({"t_us": 1.5, "yaw": 0.1, "pitch": 0.0}).encode(),
        json.dumps({"t_us": True, "yaw": 0.1, "pitch": 0.0}).encode(),
        b'{"t_us": 1, "yaw": NaN, "pitch": 0}',
        json.dumps({"t_us": 1, "yaw": "0.1", "pitch": 0.0}).encode(),
        b"{" + b" " * 2000 + b"}",
    ],
)
def test_parse_datagram_rejects_bad_input(data: bytes) -> None:
    with pytest.raises(ValueError):
        parse_gaze_datagram(data)


def test_udp_feed_receives_and_counts_rejects() -> None:
    live = LiveGaze(calibration(offset_us=0))
    feed = UdpGazeFeed(live, port=0)
    feed.start()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(json.dumps({"t_us": 100, "yaw": 0.0, "pitch": 0.0}).encode(), ("127.0.0.1", feed.port))
            sender.sendto(b"garbage", ("127.0.0.1", feed.port))
            sender.sendto(msgpack.packb({"t_us": 200, "yaw": 0.0, "pitch": 0.05}), ("127.0.0.1", feed.port))
            sender.sendto(json.dumps({"clock_offset_us": 1000}).encode(), ("127.0.0.1", feed.port))
            sender.sendto(json.dumps({"clock_offset_us": "soon"}).encode(), ("127.0.0.1", feed.port))
        deadline = time.monotonic() + 2
        while (live.received < 2 or feed.rejected < 2) and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        feed.stop()
    assert feed.stats == {"gaze_received": 2.0, "gaze_rejected": 2.0}
    assert live.clock_offset_us == 1000  # set at run time by the control datagram
    assert angles_at(live, 1200) == pytest.approx((0.0, 0.05))


def test_udp_port_in_use_is_a_device_error() -> None:
    live = LiveGaze(calibration())
    first = UdpGazeFeed(live, port=0)
    try:
        with pytest.raises(DeviceError, match="udp"):
            UdpGazeFeed(live, port=first.port)
    finally:
        first.stop()


def test_aria_without_sdk_says_how_to_install() -> None:
    try:
        import aria.stream_receiver  # noqa: F401  # imported only to learn whether it is installed
    except ImportError:
        with pytest.raises(DeviceError, match="projectaria-client-sdk"):
            AriaGen2GazeFeed(LiveGaze(calibration()))
    else:
        pytest.skip("the Aria SDK is installed here")


def test_csv_gaze_replay_of_the_sample(shared_sample_recording: Path) -> None:
    calib = load_calibration(shared_sample_recording / "calibration.json")
    mapper = csv_gaze(shared_sample_recording / "general_eye_gaze.csv", calib)
    first, last = mapper.event_time_range()
    middle = (first + last) // 2
    u, v = pixel_at(mapper, middle)
    assert 0 <= u < 1280 and 0 <= v < 720
    assert angles_at(mapper, middle) is not None
    assert pixel_at(mapper, first - 1_000_000) is None
