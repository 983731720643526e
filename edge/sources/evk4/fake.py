"""An in-process EVK4 behind a pyusb backend, for tests and demos without hardware.

``FakeEvk4`` holds the board state: a register file seeded with IMX636 reset values, the log of
every register write in order, and an EVT3 recording it serves on EP 0x81 in chunks, only while
the sensor is started (time base on and pixel reset released), optionally paced at
``rate_bytes_s`` like a live sensor. ``FakeUsbBackend`` implements
``usb.backend.IBackend`` so the real transport code runs unchanged:

    fake = FakeEvk4(recording=encode_evt3(events))
    camera = Evk4Camera(backend=FakeUsbBackend([fake]), sleep=lambda s: None)
"""

from __future__ import annotations

import array
import errno
import struct
import threading
import time
from collections import deque
from collections.abc import Iterable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core
import usb.util

from darkread.edge.events import Events
from darkread.edge.io.evt3 import encode_evt3
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4 import treuzell as tz

LIBUSB_ERROR_TIMEOUT = -7
LIBUSB_ERROR_ACCESS = -3
IDLE_POLL_S = 0.002  # how long an empty data read blocks before it times out (keeps tests fast)


def strip_raw_header(data: bytes) -> bytes:
    """The EVT3 payload of a RAW file: everything after the ``% `` header lines."""
    offset = 0
    while data.startswith(b"% ", offset):
        end = data.find(b"\n", offset)
        if end < 0:
            return b""
        offset = end + 1
    return data[offset:]


class FakeEvk4:
    """State of one fake board (thread-safe: control and data endpoints may be used concurrently)."""

    def __init__(
        self,
        *,
        recording: bytes = b"",
        chunk_bytes: int = 16 * 1024,
        rate_bytes_s: float | None = None,
        vendor_id: int = regs.CYPRESS_VID,
        product_id: int = regs.EVK4_PID,
        bcd_device: int = 0x0309,
        release_version: int = 0x030900,
        serial: int = 0x00050A2B,
        sensor_id: int = regs.IMX636_SENSOR_ID,
        failing_registers: Iterable[int] = (),
        failure_errno: int = errno.EIO,
        permission_denied: bool = False,
        roi_latches: bool = True,
    ) -> None:
        if chunk_bytes <= 0:
            raise ValueError(f"chunk_bytes must be positive, got {chunk_bytes}")
        self.recording = bytes(recording)
        self.chunk_bytes = chunk_bytes
        self.rate_bytes_s = rate_bytes_s
        self.vendor_id = vendor_id
        self.product_id = product_id
        self.bcd_device = bcd_device
        self.release_version = release_version
        self.serial = serial
        self.failing_registers = set(failing_registers)
        self.failure_errno = failure_errno
        self.permission_denied = permission_denied
        self.roi_latches = roi_latches
        self.registers: dict[int, int] = {**regs.RESET_VALUES, regs.REG_SENSOR_ID: sensor_id}
        self.writes: list[tuple[int, int]] = []
        self.reads: list[int] = []
        self.served_bytes = 0
        self._streaming_since = (0.0, 0)  # (monotonic time, served bytes) when streaming began
        self.claimed = False
        self.unplugged = False
        self._replies: deque[bytes] = deque()
        self._lock = threading.Lock()

    @classmethod
    def from_events(cls, events: Events, **kwargs: Any) -> FakeEvk4:
        """A board that serves ``events`` encoded as EVT3."""
        return cls(recording=encode_evt3(events), **kwargs)

    @classmethod
    def from_raw(cls, path: str | Path, **kwargs: Any) -> FakeEvk4:
        """A board that serves the EVT3 payload of a Prophesee RAW file."""
        return cls(recording=strip_raw_header(Path(path).read_bytes()), **kwargs)

    # --- observable state ---------------------------------------------------------------------

    @property
    def streaming(self) -> bool:
        time_base_on = self.registers.get(regs.REG_TIME_BASE_CTRL, 0) & 1
        pixels_on = self.registers.get(regs.REG_ROI_CTRL, 0) & regs.PX_TD_RSTN
        return bool(time_base_on and pixels_on)

    @property
    def exhausted(self) -> bool:
        return self.served_bytes >= len(self.recording)

    def register(self, addr: int) -> int:
        return self.registers.get(addr, 0)

    def unplug(self) -> None:
        """Every later transfer fails as on a disconnected device."""
        self.unplugged = True

    # --- control endpoint ---------------------------------------------------------------------

    def control_request(self, data: bytes) -> None:
        """Handle a frame written to EP 0x02; the reply waits for the next EP 0x82 read."""
        with self._lock:
            self._replies.append(self._answer(data))

    def control_reply(self) -> bytes | None:
        with self._lock:
            return self._replies.popleft() if self._replies else None

    def _answer(self, data: bytes) -> bytes:
        try:
            frame = tz.decode_packet(data)
        except tz.TreuzellError:
            return tz.encode_packet(tz.UNKNOWN_COMMAND)
        prop = frame.prop
        if prop in (tz.PROP_DEVICE_REG32, tz.PROP_DEVICE_REG32 | tz.WRITE_FLAG):
            return self._register_access(frame)
        if prop == tz.PROP_RELEASE_VERSION:
            return tz.encode_words(prop, self.release_version)
        if prop == tz.PROP_SERIAL:
            return tz.encode_packet(prop, struct.pack("<Q", self.serial))
        if prop == tz.PROP_BUILD_DATE:
            return tz.encode_packet(prop, struct.pack("<Q", 1_700_000_000))
        if prop == tz.PROP_DEVICE_COMPATIBLE:
            return tz.encode_packet(prop, struct.pack("<I", 0) + b"psee,ccam5_imx636\0")
        return tz.encode_packet(tz.UNKNOWN_COMMAND)

    def _register_access(self, frame: tz.Packet) -> bytes:
        prop = frame.prop
        if len(frame.payload) < 12:
            return tz.encode_words(prop | tz.FAILURE_FLAG, 0, 0, errno.EINVAL)
        device, addr, last = frame.word(0), frame.word(1), frame.word(2)
        if device != regs.SENSOR_DEVICE_ID:
            return tz.encode_words(prop | tz.FAILURE_FLAG, device, addr, errno.ENODEV)
        if addr in self.failing_registers:
            return tz.encode_words(prop | tz.FAILURE_FLAG, device, addr, self.failure_errno)
        if prop & tz.WRITE_FLAG:
            self._write_register(addr, last)
            return tz.encode_words(prop, device, addr, last)
        self.reads.append(addr)
        values = [self.registers.get(addr + 4 * i, 0) for i in range(max(last, 1))]
        return tz.encode_words(prop, device, addr, *values)

    def _write_register(self, addr: int, value: int) -> None:
        was_streaming = self.streaming
        self._store_register(addr, value)
        if self.streaming and not was_streaming:
            self._streaming_since = (time.monotonic(), self.served_bytes)

    def _store_register(self, addr: int, value: int) -> None:
        self.writes.append((addr, value))
        if addr == regs.REG_ROI_WIN_CTRL and self.roi_latches:
            # The sensor reports the window latched as soon as it is armed.
            value = value | regs.ROI_WIN_DONE if value & regs.ROI_MASTER_EN else value & ~regs.ROI_WIN_DONE
        self.registers[addr] = value & 0xFFFFFFFF

    # --- data endpoint ------------------------------------------------------------------------

    def read_data(self, size: int) -> bytes:
        """Next chunk of the recording, or b"" when stopped or exhausted."""
        with self._lock:
            if not self.streaming or self.exhausted:
                return b""
            start = self.served_bytes
            count = min(size, self.chunk_bytes, len(self.recording) - start)
            if self.rate_bytes_s is not None:
                since, served_then = self._streaming_since
                produced = served_then + int((time.monotonic() - since) * self.rate_bytes_s)
                if produced - start < count:
                    return b""  # the bridge sends full buffers; until one is filled the read times out
            self.served_bytes += count
            return self.recording[start : start + count]


def _check_plugged(board: FakeEvk4) -> None:
    if board.unplugged:
        raise usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)


class FakeUsbBackend(usb.backend.IBackend):
    """pyusb backend exposing ``FakeEvk4`` boards with the EVK4's descriptors and endpoints."""

    def __init__(self, boards: Sequence[FakeEvk4] = ()) -> None:
        super().__init__()
        self.boards = list(boards)

    # --- descriptors --------------------------------------------------------------------------

    def enumerate_devices(self) -> Iterable[FakeEvk4]:
        return iter(self.boards)

    def get_parent(self, dev: FakeEvk4) -> None:
        return None

    def get_device_descriptor(self, dev: FakeEvk4) -> SimpleNamespace:
        index = self.boards.index(dev)
        return SimpleNamespace(
            bLength=18, bDescriptorType=usb.util.DESC_TYPE_DEVICE, bcdUSB=0x0300, bDeviceClass=0,
            bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=9, idVendor=dev.vendor_id,
            idProduct=dev.product_id, bcdDevice=dev.bcd_device, iManufacturer=0, iProduct=0,
            iSerialNumber=0, bNumConfigurations=1, address=index + 2, bus=1, port_number=index + 1,
            port_numbers=(index + 1,), speed=usb.util.SPEED_SUPER,
        )  # fmt: skip

    def get_configuration_descriptor(self, dev: FakeEvk4, config: int) -> SimpleNamespace:
        if config != 0:
            raise IndexError(config)
        return SimpleNamespace(
            bLength=9, bDescriptorType=usb.util.DESC_TYPE_CONFIG, wTotalLength=9 + 9 + 3 * 7,
            bNumInterfaces=1, bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=112,
            extra_descriptors=[],
        )  # fmt: skip

    def get_interface_descriptor(self, dev: FakeEvk4, intf: int, alt: int, config: int) -> SimpleNamespace:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError((intf, alt, config))
        return SimpleNamespace(
            bLength=9, bDescriptorType=usb.util.DESC_TYPE_INTERFACE, bInterfaceNumber=0, bAlternateSetting=0,
            bNumEndpoints=3, bInterfaceClass=regs.TREUZELL_CLASS, bInterfaceSubClass=regs.TREUZELL_SUBCLASS,
            bInterfaceProtocol=0, iInterface=0, extra_descriptors=[],
        )  # fmt: skip

    def get_endpoint_descriptor(self, dev: FakeEvk4, ep: int, intf: int, alt: int, config: int) -> SimpleNamespace:
        addresses = (regs.EP_CONTROL_IN, regs.EP_CONTROL_OUT, regs.EP_DATA_IN)  # order OpenEB expects
        if (intf, alt, config) != (0, 0, 0) or not 0 <= ep < len(addresses):
            raise IndexError((ep, intf, alt, config))
        return SimpleNamespace(
            bLength=7, bDescriptorType=usb.util.DESC_TYPE_ENDPOINT, bEndpointAddress=addresses[ep],
            bmAttributes=usb.util.ENDPOINT_TYPE_BULK, wMaxPacketSize=1024, bInterval=0, bRefresh=0,
            bSynchAddress=0, extra_descriptors=[],
        )  # fmt: skip

    # --- handles and interfaces ---------------------------------------------------------------

    def open_device(self, dev: FakeEvk4) -> FakeEvk4:
        if dev.permission_denied:
            raise usb.core.USBError("Access denied (insufficient permissions)", LIBUSB_ERROR_ACCESS, errno.EACCES)
        return dev

    def close_device(self, dev_handle: FakeEvk4) -> None:
        dev_handle.claimed = False

    def set_configuration(self, dev_handle: FakeEvk4, config_value: int) -> None:
        if config_value != 1:
            raise usb.core.USBError("Invalid configuration", -2, errno.EINVAL)

    def get_configuration(self, dev_handle: FakeEvk4) -> int:
        return 1

    def set_interface_altsetting(self, dev_handle: FakeEvk4, intf: int, altsetting: int) -> None:
        if (intf, altsetting) != (0, 0):
            raise usb.core.USBError("Invalid interface", -2, errno.EINVAL)

    def claim_interface(self, dev_handle: FakeEvk4, intf: int) -> None:
        if dev_handle.claimed:
            raise usb.core.USBError("Resource busy", -6, errno.EBUSY)
        dev_handle.claimed = True

    def release_interface(self, dev_handle: FakeEvk4, intf: int) -> None:
        dev_handle.claimed = False

    def is_kernel_driver_active(self, dev_handle: FakeEvk4, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: FakeEvk4, intf: int) -> None:
        return None

    def attach_kernel_driver(self, dev_handle: FakeEvk4, intf: int) -> None:
        return None

    def clear_halt(self, dev_handle: FakeEvk4, ep: int) -> None:
        return None

    def reset_device(self, dev_handle: FakeEvk4) -> None:
        return None

    # --- transfers ----------------------------------------------------------------------------

    def bulk_write(self, dev_handle: FakeEvk4, ep: int, intf: int, data: array.array, timeout: int) -> int:
        _check_plugged(dev_handle)
        if ep != regs.EP_CONTROL_OUT:
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        payload = data.tobytes()
        dev_handle.control_request(payload)
        return len(payload)

    def bulk_read(self, dev_handle: FakeEvk4, ep: int, intf: int, buff: array.array, timeout: int) -> int:
        _check_plugged(dev_handle)
        capacity = len(buff) * buff.itemsize
        if ep == regs.EP_CONTROL_IN:
            reply = dev_handle.control_reply()
        elif ep == regs.EP_DATA_IN:
            reply = dev_handle.read_data(capacity) or None
        else:
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        if reply is None:
            time.sleep(min(timeout / 1000, IDLE_POLL_S) if timeout else IDLE_POLL_S)
            raise usb.core.USBTimeoutError("Operation timed out", LIBUSB_ERROR_TIMEOUT, errno.ETIMEDOUT)
        if len(reply) > capacity:
            raise usb.core.USBError("Overflow", -8, errno.EOVERFLOW)
        memoryview(buff).cast("B")[: len(reply)] = reply
        return len(reply)
