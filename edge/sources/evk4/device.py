"""pyusb transport to an EVK4-class board: discovery, claiming, Treuzell control, bulk data.

Control frames go out on EP 0x02 and come back on EP 0x82 under one lock (replies must pair
with their requests even when the reader thread is busy on EP 0x81). Event data is read from
EP 0x81 by whoever calls ``read_data`` (the camera's drain thread).
"""

from __future__ import annotations

import errno
import logging
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import usb.core
import usb.util

from darkread.edge.errors import DeviceError
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4 import treuzell as tz

log = logging.getLogger(__name__)

UDEV_RULE_NAME = "99-darkread-evk4.rules"
UDEV_RULE_SOURCE = Path(__file__).resolve().parents[2] / "systemd" / UDEV_RULE_NAME
UDEV_RULE_INSTALLED = Path("/etc/udev/rules.d") / UDEV_RULE_NAME
UDEV_HINT = (
    f"install the udev rule: sudo cp {UDEV_RULE_SOURCE} {UDEV_RULE_INSTALLED} && "
    "sudo udevadm control --reload-rules && sudo udevadm trigger, "
    "then add your user to the 'darkread' group and re-plug the camera"
)

Sleep = Callable[[float], None]


def describe_ids(ids: Iterable[tuple[int, int, str]] = regs.SUPPORTED_USB_IDS) -> str:
    return ", ".join(f"{vid:04x}:{pid:04x} ({name})" for vid, pid, name in ids)


def _is_supported(dev: usb.core.Device) -> bool:
    return any(dev.idVendor == vid and dev.idProduct == pid for vid, pid, _ in regs.SUPPORTED_USB_IDS)


def find_candidates(backend: object | None = None) -> list[usb.core.Device]:
    """Every attached board with a supported vendor:product id."""
    try:
        return list(usb.core.find(find_all=True, backend=backend, custom_match=_is_supported))
    except usb.core.NoBackendError as exc:
        raise DeviceError(
            "pyusb found no libusb backend: install libusb-1.0 (Debian/Ubuntu: apt install libusb-1.0-0)"
        ) from exc


def _usb_error(action: str, exc: usb.core.USBError) -> DeviceError:
    if exc.errno in (errno.EACCES, errno.EPERM):
        return DeviceError(f"permission denied while trying to {action} the camera: {UDEV_HINT}")
    if exc.errno == errno.EBUSY:
        return DeviceError(f"camera is busy while trying to {action} it: another program has claimed it")
    if exc.errno == errno.ENODEV:
        return DeviceError(f"camera disappeared while trying to {action} it (unplugged?)")
    return DeviceError(f"USB error while trying to {action} the camera: {exc}")


class Evk4Device:
    """A claimed Treuzell interface; use ``Evk4Device.open`` to find and claim one."""

    def __init__(self, dev: usb.core.Device, *, sleep: Sleep = time.sleep) -> None:
        self.dev = dev
        self.sleep = sleep
        self._control_lock = threading.Lock()
        self._claimed = False
        self.release_version = 0
        self.serial = ""
        self._data_buffer = usb.util.create_buffer(0)

    @classmethod
    def open(cls, *, serial: str | None = None, backend: object | None = None, sleep: Sleep = time.sleep) -> Evk4Device:
        """Claim the first supported board (or the one whose serial matches)."""
        candidates = find_candidates(backend)
        if not candidates:
            raise DeviceError(
                f"no event camera found on USB (searched {describe_ids()}). "
                f"Check the cable and power; if the camera is plugged in, {UDEV_HINT}"
            )
        seen: list[str] = []
        errors: list[DeviceError] = []
        for dev in candidates:
            device = cls(dev, sleep=sleep)
            try:
                device.claim()
            except DeviceError as exc:  # busy or inaccessible: another board may still do
                errors.append(exc)
                continue
            if serial is None or device.serial.lower() == serial.lower():
                return device
            seen.append(device.serial)
            device.release()
        if errors and (serial is None or not seen):
            raise errors[0]
        unopened = f"; {len(errors)} more could not be opened ({errors[0]})" if errors else ""
        raise DeviceError(f"no camera with serial {serial!r}; found serials {', '.join(seen)}{unopened}")

    @property
    def usb_id(self) -> str:
        return f"{self.dev.idVendor:04x}:{self.dev.idProduct:04x}"

    def claim(self) -> None:
        """Claim interface 0, select alt 0 when the firmware supports it, read serial and version."""
        intf = regs.TREUZELL_INTERFACE
        try:
            try:
                if self.dev.is_kernel_driver_active(intf):
                    self.dev.detach_kernel_driver(intf)
            except (NotImplementedError, usb.core.USBError) as exc:
                if isinstance(exc, usb.core.USBError) and exc.errno in (errno.EACCES, errno.EPERM):
                    raise
            usb.util.claim_interface(self.dev, intf)
            self._claimed = True
            if self.dev.bcdDevice >= regs.MIN_BCD_DEVICE_FOR_ALTSETTING:
                self.dev.set_interface_altsetting(interface=intf, alternate_setting=0)
        except usb.core.USBError as exc:
            self.release()
            raise _usb_error("claim", exc) from exc
        try:
            try:
                self.release_version = self.request(tz.PROP_RELEASE_VERSION).word(0)
            except tz.TreuzellError:
                self.release_version = 0
            self.serial = self._read_serial()
        except DeviceError:
            self.release()
            raise

    def _read_serial(self) -> str:
        reply = self.request(tz.PROP_SERIAL)
        return f"{reply.u64():08x}" if len(reply.payload) >= 8 else f"{reply.word(0):08x}"

    def request(self, prop: int, payload: bytes = b"") -> tz.Packet:
        """One control round trip; DeviceError subclasses on USB or protocol failure."""
        frame = tz.encode_packet(prop, payload)
        with self._control_lock:
            try:
                self.dev.write(regs.EP_CONTROL_OUT, frame, regs.CONTROL_WRITE_TIMEOUT_MS)
                answer = self.dev.read(regs.EP_CONTROL_IN, tz.MAX_REPLY_BYTES, regs.CONTROL_READ_TIMEOUT_MS)
            except usb.core.USBTimeoutError as exc:
                raise DeviceError(f"camera did not answer control property 0x{prop:08X} in time") from exc
            except usb.core.USBError as exc:
                raise _usb_error("talk to", exc) from exc
        return tz.check_reply(prop, bytes(answer))

    def read_register(self, addr: int) -> int:
        reply = self._register_request(tz.PROP_DEVICE_REG32, addr, 1)
        tz.check_register_reply(reply, addr, regs.SENSOR_DEVICE_ID)
        return reply.word(2)

    def write_register(self, addr: int, value: int) -> None:
        reply = self._register_request(tz.PROP_DEVICE_REG32 | tz.WRITE_FLAG, addr, value)
        tz.check_register_reply(reply, addr, regs.SENSOR_DEVICE_ID)

    def _register_request(self, prop: int, addr: int, last_word: int) -> tz.Packet:
        payload = tz.encode_words(0, regs.SENSOR_DEVICE_ID, addr, last_word)[tz.HEADER_BYTES :]
        try:
            return self.request(prop, payload)
        except tz.CommandFailedError as exc:
            action = "write" if prop & tz.WRITE_FLAG else "read"
            raise tz.CommandFailedError(prop, exc.errno, f" ({action} of register 0x{addr:04X})") from exc

    def apply(self, sequence: regs.RegisterSequence) -> None:
        """Run a register sequence; ``Field`` operations read the register first."""
        for op in sequence:
            if isinstance(op, regs.Write):
                self.write_register(op.addr, op.value)
            elif isinstance(op, regs.Field):
                current = self.read_register(op.addr)
                self.write_register(op.addr, (current & ~op.mask) | (op.value & op.mask))
            else:
                self.sleep(op.us * 1e-6)

    def read_data(self, size: int, timeout_ms: int = regs.DATA_READ_TIMEOUT_MS) -> bytes:
        """Up to ``size`` bytes of EVT3 from EP 0x81; empty on timeout."""
        if len(self._data_buffer) != size:
            self._data_buffer = usb.util.create_buffer(size)
        try:
            count = self.dev.read(regs.EP_DATA_IN, self._data_buffer, timeout_ms)
            return memoryview(self._data_buffer)[:count].tobytes()
        except usb.core.USBTimeoutError:
            return b""
        except usb.core.USBError as exc:
            raise _usb_error("read events from", exc) from exc

    def release(self) -> None:
        """Release the interface and the handle; safe to call twice."""
        if self._claimed:
            try:
                usb.util.release_interface(self.dev, regs.TREUZELL_INTERFACE)
            except usb.core.USBError as exc:
                log.debug("releasing interface failed: %s", exc)
            self._claimed = False
        usb.util.dispose_resources(self.dev)
