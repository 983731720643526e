"""Evk4Camera against the fake board: bring-up order, biases, ERC, ROI and error paths."""

from __future__ import annotations

import errno
from typing import Any

import pytest

from darkread.edge.errors import DeviceError
from darkread.edge.events import Events
from darkread.edge.sources.base import EventSource
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4.camera import ROI_FOLLOW_MARGIN_PX, Evk4Camera
from darkread.edge.sources.evk4.fake import FakeEvk4, FakeUsbBackend

DOCUMENTED_START_WRITES = [(0xB000, 0x2F9), (0x9028, 0), (0x9008, 0x645), (0x002C, 0x0022C724), (0x0004, 0xF0005442)]
DOCUMENTED_STOP_WRITES = [(0x0004, 0xF0005042), (0x002C, 0x0022C324), (0x9028, 2), (0x9008, 0x644), (0xB000, 0x2F8)]


class SilentDecoder:
    """For tests where the fake serves no data: decoding is not what they check."""

    def decode(self, chunk: bytes) -> tuple[Events, object]:
        raise AssertionError(f"unexpected {len(chunk)} bytes of event data")


def camera_on(fake: FakeEvk4, **kwargs: Any) -> Evk4Camera:
    kwargs.setdefault("sleep", lambda seconds: None)
    kwargs.setdefault("decoder_factory", SilentDecoder)
    return Evk4Camera(backend=FakeUsbBackend([fake]), **kwargs)


def simulate(sequence: regs.RegisterSequence, registers: dict[int, int]) -> list[tuple[int, int]]:
    """Writes a sequence must produce on a register file (Field = read-modify-write)."""
    writes = []
    for op in sequence:
        if isinstance(op, regs.Write):
            registers[op.addr] = op.value
        elif isinstance(op, regs.Field):
            registers[op.addr] = (registers.get(op.addr, 0) & ~op.mask) | (op.value & op.mask)
        else:
            continue
        writes.append((op.addr, registers[op.addr]))
    return writes


def write_values(sequence: regs.RegisterSequence) -> list[tuple[int, int]]:
    return [(op.addr, op.value) for op in sequence if isinstance(op, regs.Write)]


def test_camera_is_an_event_source() -> None:
    assert isinstance(camera_on(FakeEvk4()), EventSource)


def test_open_runs_stop_destroy_init_then_format_erc_roi_in_order() -> None:
    fake = FakeEvk4()
    camera_on(fake).open()
    registers = dict(regs.RESET_VALUES)
    expected = []
    for sequence in (regs.STOP, regs.DESTROY, regs.INIT, regs.FORMAT_EVT3, regs.erc_init_sequence(), regs.ROI_LINES_RESET):
        expected += simulate(sequence, registers)
    expected += simulate(regs.erc_sequence(20e6), registers)
    assert fake.writes == expected
    init_start = len(simulate(regs.STOP, dict(regs.RESET_VALUES))) + len(write_values(regs.DESTROY))
    assert fake.writes[init_start : init_start + 67] == write_values(regs.INIT)
    assert fake.reads[:2] == [regs.REG_SENSOR_ID, regs.REG_SENSOR_VARIANT]


def test_open_sleeps_the_documented_delays_through_the_injected_sleep() -> None:
    slept: list[float] = []
    camera_on(FakeEvk4(), sleep=slept.append).open()
    documented_us = sum(regs.sequence_delay_us(s) for s in (regs.STOP, regs.DESTROY, regs.INIT))
    assert sum(slept) == pytest.approx(documented_us * 1e-6)
    assert slept[:2] == [0.001, 0.0003]  # the stop sequence comes first


def test_start_and_stop_write_the_documented_sequences() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.open()
    mark = len(fake.writes)
    camera.start(lambda events: None)
    assert fake.writes[mark:] == DOCUMENTED_START_WRITES and fake.streaming
    mark = len(fake.writes)
    camera.stop()
    assert fake.writes[mark:] == DOCUMENTED_STOP_WRITES and not fake.streaming
    camera.stop()  # idempotent
    assert len(fake.writes) == mark + len(DOCUMENTED_STOP_WRITES)


def test_close_powers_down_and_releases() -> None:
    fake = FakeEvk4()
    with camera_on(fake) as camera:
        camera.start(lambda events: None)
        mark = len(fake.writes)
    assert fake.writes[mark:] == DOCUMENTED_STOP_WRITES + write_values(regs.DESTROY)
    assert not fake.claimed and not camera.is_open
    camera.close()


def test_biases_are_offsets_from_factory_values() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake, biases={"diff_off": 20})
    camera.open()
    assert (0x1018, 0x49 + 20 | 0x11A10000) in fake.writes
    mark = len(fake.writes)
    camera.set_biases(diff_on=10, refr=-5, hpf=0)
    assert fake.writes[mark:] == [(0x1010, 0x11A10070), (0x1020, 0x11A1000F), (0x100C, 0x11A10000)]
    assert camera.biases == {"fo": 0, "hpf": 0, "diff_on": 10, "diff_off": 20, "refr": -5}


def test_bias_below_zero_is_clipped_like_openeb() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.open()
    camera.set_biases(fo=-150)  # factory 0x53 = 83, 83 - 150 < 0
    assert fake.writes[-1] == (0x1004, 0x11A10000)


@pytest.mark.parametrize(
    ("offsets", "message"),
    [
        ({"diff_on": 201}, r"bias diff_on offset 201 is outside the allowed range \[-150, 200\]"),
        ({"refr": -51}, r"allowed range \[-50, 255\] \(recommended \[-20, 235\]"),
        ({"hpf": -1}, r"allowed range \[0, 255\]"),
        ({"diff": 3}, "reference of diff_on/diff_off"),
        ({"bogus": 1}, "settable biases: fo, hpf, diff_on, diff_off, refr"),
    ],
)
def test_bias_range_errors(offsets: dict[str, int], message: str) -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.open()
    mark = len(fake.writes)
    with pytest.raises(ValueError, match=message):
        camera.set_biases(**offsets)
    with pytest.raises(ValueError, match=message):
        camera_on(FakeEvk4(), biases=offsets)
    assert len(fake.writes) == mark


def test_erc_default_and_changes() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.open()
    assert fake.register(regs.REG_ERC_TARGET_EVENT_COUNT) == 4000 and fake.register(regs.REG_ERC_T_DROPPING) == 1
    mark = len(fake.writes)
    camera.set_erc(1e6)
    camera.set_erc(None)
    assert fake.writes[mark:] == [(0x600C, 200), (0x6050, 1), (0x6050, 0)]
    with pytest.raises(ValueError, match="ERC rate"):
        camera.set_erc(5e9)
    assert len(fake.writes) == mark + 3


def test_erc_disabled_at_open() -> None:
    fake = FakeEvk4()
    camera_on(fake, erc_rate_ev_s=None).open()
    assert fake.writes[-1] == (0x6050, 0) and fake.register(regs.REG_ERC_TARGET_EVENT_COUNT) == 4000


def test_roi_window_writes_and_full_frame_restore() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.open()
    mark = len(fake.writes)
    camera.set_roi(100, 200, 200, 100)
    roi_ctrl = 0xF0005042 | regs.ROI_TD_EN | regs.ROI_TD_SHADOW_TRIGGER | regs.ROI_TD_RONI_N_EN
    assert fake.writes[mark:] == [
        (0x0038, 100 | 200 << 16), (0x003C, 300 | 300 << 16), (0x0034, 1), (0x0004, roi_ctrl),
    ]  # fmt: skip
    assert camera.roi == (100, 200, 200, 100)
    camera.set_roi(100, 200, 200, 100)  # unchanged: no USB traffic
    mark = len(fake.writes)
    camera.set_roi(0, 0, 1280, 720)
    assert fake.writes[mark:] == [(0x0034, 0), (0x0004, 0xF0005042 | regs.ROI_TD_SHADOW_TRIGGER)]
    assert camera.roi == (0, 0, 1280, 720) and camera.stats["roi_writes"] == 2


def test_roi_set_before_open_is_applied_at_open() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake)
    camera.set_roi(10, 20, 30, 40)
    assert fake.writes == []
    camera.open()
    assert (0x0038, 10 | 20 << 16) in fake.writes and camera.roi == (10, 20, 30, 40)


def test_roi_follow_pads_and_rewrites_only_when_gaze_leaves_the_window() -> None:
    fake = FakeEvk4()
    camera = camera_on(fake, roi_follow=True)
    camera.open()
    camera.set_roi(500, 300, 200, 100)
    m = ROI_FOLLOW_MARGIN_PX
    assert camera.roi == (500 - m, 300 - m, 200 + 2 * m, 100 + 2 * m)
    mark = len(fake.writes)
    camera.set_roi(500 + m, 300 - m, 200, 100)  # still inside the padded window
    assert len(fake.writes) == mark
    camera.set_roi(1100, 650, 180, 70)  # leaves it; padding is clipped at the sensor edge
    assert camera.roi == (1100 - m, 650 - m, 180 + m, 70 + m)


def test_roi_outside_sensor_is_rejected() -> None:
    with pytest.raises(ValueError, match="leaves the 1280x720 sensor"):
        camera_on(FakeEvk4()).set_roi(1200, 0, 100, 10)


def test_roi_that_never_latches_raises() -> None:
    camera = camera_on(FakeEvk4(roi_latches=False))
    camera.open()
    with pytest.raises(DeviceError, match="did not latch ROI window"):
        camera.set_roi(0, 0, 100, 100)


def test_failure_flag_during_init_raises_and_releases_the_board() -> None:
    fake = FakeEvk4(failing_registers={0xB07C}, failure_errno=errno.ETIMEDOUT)
    camera = camera_on(fake)
    with pytest.raises(DeviceError, match="register 0xB07C.*ETIMEDOUT"):
        camera.open()
    assert not fake.claimed and not camera.is_open


def test_old_firmware_is_refused() -> None:
    fake = FakeEvk4(release_version=0x030700)
    with pytest.raises(DeviceError, match=r"firmware 3\.7\.0, too old \(need 3\.8\.0 or newer\)"):
        camera_on(fake).open()
    assert not fake.claimed and fake.writes == []


def test_firmware_rule_applies_only_to_cypress_boards() -> None:
    fake = FakeEvk4(vendor_id=0x31F7, product_id=0x0003, release_version=0x010000)
    camera_on(fake).open()
    assert fake.claimed


def test_other_sensor_is_refused() -> None:
    fake = FakeEvk4(sensor_id=0xA0301003)
    with pytest.raises(DeviceError, match="sensor id 0xA0301003.*only the IMX636"):
        camera_on(fake).open()
    assert fake.writes == []


def test_no_device_error_mentions_udev_rule() -> None:
    with pytest.raises(DeviceError, match="no event camera found.*04b4:00f5.*99-darkread-evk4.rules"):
        camera_on(FakeEvk4(vendor_id=0x1234)).open()


@pytest.mark.parametrize("size", [0, 1000, -1024])
def test_transfer_size_must_be_whole_usb_packets(size: int) -> None:
    with pytest.raises(ValueError, match="multiple of 1024"):
        Evk4Camera(backend=FakeUsbBackend([]), transfer_bytes=size)
