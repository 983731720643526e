"""Discovery, claiming and control round trips through pyusb against the fake backend."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
import usb.core

from darkread.edge.errors import DeviceError
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4.device import UDEV_RULE_SOURCE, Evk4Device, find_candidates
from darkread.edge.sources.evk4.fake import FakeEvk4, FakeUsbBackend, strip_raw_header
from darkread.edge.sources.evk4.treuzell import CommandFailedError


def no_sleep(seconds: float) -> None:
    pass


@pytest.mark.parametrize(
    ("vid", "pid"), [(0x04B4, 0x00F5), (0x04B4, 0x00F4), (0x31F7, 0x0003), (0x1409, 0x8E00)]
)
def test_supported_boards_are_discovered(vid: int, pid: int) -> None:
    fake = FakeEvk4(vendor_id=vid, product_id=pid)
    found = find_candidates(FakeUsbBackend([fake]))
    assert [(d.idVendor, d.idProduct) for d in found] == [(vid, pid)]


def test_bootloader_and_other_devices_are_ignored() -> None:
    boards = [FakeEvk4(product_id=regs.BOOTLOADER_PID), FakeEvk4(vendor_id=0x1234, product_id=0x5678)]
    assert find_candidates(FakeUsbBackend(boards)) == []


def test_no_device_names_searched_ids_and_udev_rule() -> None:
    with pytest.raises(DeviceError) as info:
        Evk4Device.open(backend=FakeUsbBackend([]))
    message = str(info.value)
    assert "04b4:00f5" in message and "04b4:00f4" in message and "31f7:0003" in message
    assert "99-darkread-evk4.rules" in message and "udevadm" in message


def test_permission_denied_points_at_the_udev_rule() -> None:
    with pytest.raises(DeviceError, match="permission denied.*99-darkread-evk4.rules"):
        Evk4Device.open(backend=FakeUsbBackend([FakeEvk4(permission_denied=True)]))


def test_claim_reads_serial_and_firmware_and_holds_interface() -> None:
    fake = FakeEvk4(serial=0xABCDEF, release_version=0x030A01)
    device = Evk4Device.open(backend=FakeUsbBackend([fake]), sleep=no_sleep)
    assert (device.serial, device.release_version, fake.claimed) == ("00abcdef", 0x030A01, True)
    device.release()
    assert not fake.claimed


def test_busy_camera_is_reported() -> None:
    fake = FakeEvk4()
    first = Evk4Device.open(backend=FakeUsbBackend([fake]))
    with pytest.raises(DeviceError, match="busy"):
        Evk4Device.open(backend=FakeUsbBackend([fake]))
    first.release()


def test_a_busy_board_does_not_hide_a_free_one() -> None:
    busy, free = FakeEvk4(serial=1), FakeEvk4(serial=2)
    holder = Evk4Device.open(backend=FakeUsbBackend([busy]))
    device = Evk4Device.open(backend=FakeUsbBackend([busy, free]))
    assert device.serial == "00000002"
    holder.release()
    device.release()


def test_serial_selects_among_several_boards() -> None:
    boards = [FakeEvk4(serial=1), FakeEvk4(serial=2)]
    device = Evk4Device.open(serial="00000002", backend=FakeUsbBackend(boards))
    assert device.serial == "00000002" and boards[1].claimed and not boards[0].claimed
    with pytest.raises(DeviceError, match=r"no camera with serial '00000009'; found serials 00000001"):
        Evk4Device.open(serial="00000009", backend=FakeUsbBackend([boards[0]]))


def test_register_round_trip_and_field_update() -> None:
    fake = FakeEvk4()
    device = Evk4Device.open(backend=FakeUsbBackend([fake]))
    assert device.read_register(regs.REG_SENSOR_ID) == regs.IMX636_SENSOR_ID
    device.write_register(0x1234, 0xDEADBEEF)
    device.apply((regs.Field(0x1234, 0x0000FF00, 0x00001200),))
    assert fake.writes == [(0x1234, 0xDEADBEEF), (0x1234, 0xDEAD12EF)]
    assert device.read_register(0x1234) == 0xDEAD12EF


def test_delays_go_through_the_injected_sleep() -> None:
    slept: list[float] = []
    device = Evk4Device.open(backend=FakeUsbBackend([FakeEvk4()]), sleep=slept.append)
    device.apply((regs.Delay(1_000_000), regs.Write(0x1C, 1), regs.Delay(300)))
    assert slept == [1.0, 0.0003]


def test_failure_flag_becomes_device_error_with_errno_and_address() -> None:
    fake = FakeEvk4(failing_registers={0x1010}, failure_errno=errno.EIO)
    device = Evk4Device.open(backend=FakeUsbBackend([fake]))
    with pytest.raises(CommandFailedError, match="write of register 0x1010.*errno 5") as info:
        device.write_register(0x1010, 1)
    assert isinstance(info.value, DeviceError) and info.value.errno == errno.EIO
    with pytest.raises(DeviceError, match="read of register 0x1010"):
        device.read_register(0x1010)


def test_data_endpoint_is_silent_until_started() -> None:
    fake = FakeEvk4(recording=bytes(range(200)), chunk_bytes=64)
    device = Evk4Device.open(backend=FakeUsbBackend([fake]))
    assert device.read_data(1024, timeout_ms=5) == b""
    device.apply(regs.START)
    assert device.read_data(1024) == bytes(range(64))
    assert device.read_data(1024) == bytes(range(64, 128))
    device.apply(regs.STOP)
    assert device.read_data(1024, timeout_ms=5) == b""


def test_fake_rejects_writes_to_the_data_endpoint() -> None:
    dev = usb.core.find(backend=FakeUsbBackend([FakeEvk4()]))
    assert dev is not None
    with pytest.raises(usb.core.USBError):
        dev.write(0x81, b"x")


def test_strip_raw_header() -> None:
    assert strip_raw_header(b"% evt 3.0\n% end\n\x01\x02") == b"\x01\x02"
    assert strip_raw_header(b"\x01\x02") == b"\x01\x02"


def test_udev_rule_grants_the_darkread_group() -> None:
    rule = Path(UDEV_RULE_SOURCE).read_text()
    for pid in ("00f5", "00f4"):
        assert f'ATTR{{idVendor}}=="04b4", ATTR{{idProduct}}=="{pid}"' in rule
    assert rule.count('GROUP="darkread"') >= 2 and 'MODE="0660"' in rule
