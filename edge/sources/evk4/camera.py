"""``Evk4Camera``: the live IMX636 event source (EVK4 / EVK3 HD) as an ``EventSource``.

Two threads keep the sensor drained even on slow ARM hosts: the drain thread does nothing but
read EP 0x81 into a bounded byte queue (a stalled endpoint overflows the sensor FIFO), and the
decode thread turns those bytes into event arrays and hands them to the sink. When the sink
falls behind, whole USB chunks are dropped and counted rather than stalling the endpoint; the
decoder then resumes at the next point where the EVT3 state is fully known (``resync``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from usb.util import SPEED_SUPER

from darkread.core.errors import DarkreadError
from darkread.edge.errors import DeviceError
from darkread.edge.events import Events
from darkread.edge.roi import ROI_FOLLOW_MARGIN_PX, follow_window
from darkread.edge.sources.base import EventSink
from darkread.edge.sources.evk4 import registers as regs
from darkread.edge.sources.evk4.bias_profiles import check_bias_offsets
from darkread.edge.sources.evk4.device import Evk4Device, Sleep
from darkread.edge.sources.evk4.resync import ChunkAligner
from darkread.edge.sources.evk4.treuzell import format_version

log = logging.getLogger(__name__)

ROI_POLL_ATTEMPTS = 50
DEFAULT_QUEUE_BYTES = 64 * 1024 * 1024
USB_PACKET_BYTES = 1024  # SuperSpeed bulk packet; reads must be whole packets
COALESCE_BYTES = 4 * 1024 * 1024  # largest buffer the decode thread builds from queued chunks


class Decoder(Protocol):
    def decode(self, chunk: bytes) -> tuple[Events, Any]: ...


def _default_decoder() -> Decoder:
    from darkread.edge.io.evt3 import Evt3Decoder  # lazy: the compiled decoder loads with the first stream

    return Evt3Decoder(width=regs.WIDTH, height=regs.HEIGHT)


class Evk4Camera:
    """A Prophesee EVK4 (or EVK3 HD / compatible) read live over USB.

    ``biases`` are offsets from the factory values (0 = factory); ``erc_rate_ev_s`` caps the event
    rate in the sensor (``None`` disables the controller); with ``roi_follow`` each ``set_roi``
    (called with the gaze window) programs a slightly larger window and skips USB writes while
    the gaze stays inside it. ``backend`` is a pyusb backend (``FakeUsbBackend`` in tests);
    ``sleep`` runs the register-sequence delays (tests pass a no-op).
    """

    width: int = regs.WIDTH
    height: int = regs.HEIGHT

    def __init__(
        self,
        *,
        serial: str | None = None,
        biases: dict[str, int] | None = None,
        erc_rate_ev_s: float | None = 20e6,
        roi_follow: bool = False,
        backend: object | None = None,
        transfer_bytes: int = 128 * 1024,
        sleep: Sleep = time.sleep,
        decoder_factory: Callable[[], Decoder] = _default_decoder,
        max_queue_bytes: int = DEFAULT_QUEUE_BYTES,
    ) -> None:
        if transfer_bytes <= 0 or transfer_bytes % USB_PACKET_BYTES:
            raise ValueError(f"transfer_bytes must be a positive multiple of {USB_PACKET_BYTES}, got {transfer_bytes}")
        check_bias_offsets(biases or {})
        if erc_rate_ev_s is not None:
            regs.erc_event_count(erc_rate_ev_s)
        self.serial = serial
        self.roi_follow = roi_follow
        self.transfer_bytes = transfer_bytes
        self._backend = backend
        self._sleep = sleep
        self._decoder_factory = decoder_factory
        self._max_queue_bytes = max_queue_bytes
        self._bias_offsets: dict[str, int] = dict(biases or {})
        self._factory_biases: dict[str, int] = {}
        self._erc_rate = erc_rate_ev_s
        self._roi: tuple[int, int, int, int] | None = None  # programmed window, None = full frame
        self._device: Evk4Device | None = None
        self._config_lock = threading.RLock()
        self._stop_event = threading.Event()
        self._queue: queue.SimpleQueue[tuple[int, bytes] | None] = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self._reader_error: DarkreadError | None = None
        self._counts_lock = threading.Lock()
        self._counts = dict.fromkeys(
            ("bytes_read", "usb_reads", "usb_timeouts", "events", "triggers", "dropped_bytes",
             "queued_bytes", "stream_gaps", "skipped_bytes", "decode_errors", "sink_errors", "roi_writes"), 0,
        )  # fmt: skip
        self._started_at: float | None = None
        self._stopped_at: float | None = None

    # --- lifecycle ----------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self._device is not None

    @property
    def is_running(self) -> bool:
        return bool(self._threads)

    @property
    def device_serial(self) -> str:
        """Serial number the open board reports (Treuzell property 0x72)."""
        return self._require_device().serial

    def open(self) -> None:
        """Find and claim the board, check firmware and sensor, then bring the sensor up."""
        if self._device is not None:
            return
        device = Evk4Device.open(serial=self.serial, backend=self._backend, sleep=self._sleep)
        try:
            self._check_board(device)
            self._device = device
            with self._config_lock:
                for sequence in (regs.STOP, regs.DESTROY, regs.INIT, regs.FORMAT_EVT3):
                    device.apply(sequence)
                device.apply(regs.erc_init_sequence())
                device.apply(regs.ROI_LINES_RESET)
                self._factory_biases = {
                    name: device.read_register(spec.addr) & regs.BIAS_VALUE_MASK for name, spec in regs.BIASES.items()
                }
                self._write_biases(self._bias_offsets)
                device.apply(regs.erc_sequence(self._erc_rate))
                requested, self._roi = self._roi, None
                if requested is not None:
                    self._program_roi(requested)
        except BaseException:
            self._device = None
            device.release()
            raise
        log.info(
            "EVK camera %s (serial %s, firmware %s) ready",
            device.usb_id, device.serial, format_version(device.release_version),
        )  # fmt: skip

    def _check_board(self, device: Evk4Device) -> None:
        dev = device.dev
        if dev.idVendor == regs.CYPRESS_VID and dev.idProduct in (regs.EVK4_PID, regs.EVK3_PID):
            if device.release_version < regs.MIN_FIRMWARE_VERSION:
                raise DeviceError(
                    f"camera {device.serial} runs firmware {format_version(device.release_version)}, too old "
                    f"(need {format_version(regs.MIN_FIRMWARE_VERSION)} or newer): update it with Prophesee's "
                    "firmware tool (see https://support.prophesee.ai)"
                )
        if dev.speed is not None and dev.speed < SPEED_SUPER:
            log.warning("camera %s is not on a SuperSpeed (USB 3) port: expect dropped events", device.serial)
        sensor_id = device.read_register(regs.REG_SENSOR_ID)
        variant = device.read_register(regs.REG_SENSOR_VARIANT)
        if sensor_id != regs.IMX636_SENSOR_ID or variant & 3:
            raise DeviceError(
                f"camera {device.serial} ({device.usb_id}) reports sensor id 0x{sensor_id:08X} / variant "
                f"{variant & 3}; this driver supports only the IMX636 (id 0x{regs.IMX636_SENSOR_ID:08X}, variant 0)"
            )

    def start(self, sink: EventSink, raw_sink: Callable[[bytes], object] | None = None) -> None:
        """Open if needed, start the drain and decode threads, then start the sensor.

        ``raw_sink`` (optional) receives every USB chunk as read, on the drain thread, before
        any drop: for recording RAW files. It must be fast.
        """
        if self._threads:
            raise RuntimeError("camera already started; call stop() first")
        self.open()
        device = self._require_device()
        decoder = self._decoder_factory()
        self._stop_event.clear()
        self._reader_error = None
        self._queue = queue.SimpleQueue()
        with self._counts_lock:  # stream counters describe the current run
            self._counts.update({k: 0 for k in self._counts if k != "roi_writes"})
        self._threads = [
            threading.Thread(target=self._decode_loop, args=(decoder, sink), name="evk4-decode", daemon=True),
            threading.Thread(target=self._drain_loop, args=(device, raw_sink), name="evk4-drain", daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        self._started_at, self._stopped_at = time.monotonic(), None
        try:
            with self._config_lock:
                device.apply(regs.START)
        except BaseException:
            self._join_threads()
            raise

    def stop(self) -> None:
        """Stop the sensor, then the threads.

        Chunks already read from USB still reach the sink before this returns; none after.
        """
        if not self._threads:
            return
        error: DeviceError | None = None
        if self._device is not None:
            try:
                with self._config_lock:
                    self._device.apply(regs.STOP)
            except DeviceError as exc:
                error = exc
        self._join_threads()
        self._stopped_at = time.monotonic()
        if error is not None:
            raise error

    def _join_threads(self) -> None:
        self._stop_event.set()
        decode_thread, drain_thread = self._threads
        drain_thread.join()
        self._queue.put(None)
        decode_thread.join()
        self._threads = []

    def close(self) -> None:
        """Stop, power the sensor down and release the USB interface; best effort, safe to call twice."""
        try:
            self.stop()
        except DeviceError as exc:
            log.warning("stopping the sensor failed: %s", exc)
        finally:
            device, self._device = self._device, None
            if device is not None:
                try:
                    with self._config_lock:
                        device.apply(regs.DESTROY)
                except DeviceError as exc:
                    log.warning("powering the sensor down failed: %s", exc)
                finally:
                    device.release()

    def __enter__(self) -> Evk4Camera:
        self.open()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- threads ------------------------------------------------------------------------------

    def _drain_loop(self, device: Evk4Device, raw_sink: Callable[[bytes], object] | None) -> None:
        offset = 0  # position of the next byte in the sensor's stream, dropped bytes included
        while not self._stop_event.is_set():
            try:
                data = device.read_data(self.transfer_bytes)
            except DeviceError as exc:
                log.error("event stream stopped: %s", exc)
                self._reader_error = exc
                return
            if data and raw_sink is not None:
                try:
                    raw_sink(data)
                except Exception as exc:  # e.g. disk full while recording: end the stream, say why
                    log.error("raw data sink failed, stream stopped: %s", exc)
                    self._reader_error = DarkreadError(f"raw data sink failed: {exc}")
                    return
            with self._counts_lock:
                counts = self._counts
                counts["usb_reads"] += 1
                if not data:
                    counts["usb_timeouts"] += 1
                    continue
                counts["bytes_read"] += len(data)
                offset += len(data)
                if counts["queued_bytes"] + len(data) > self._max_queue_bytes:
                    counts["dropped_bytes"] += len(data)
                    continue
                counts["queued_bytes"] += len(data)
            self._queue.put((offset - len(data), data))

    def _next_batch(self) -> tuple[list[tuple[int, bytes]], bool]:
        """Everything queued (up to ``COALESCE_BYTES``), and whether the stream ended.

        Decoding a few large buffers costs far less than many small ones, which is what lets a
        slow host catch up after a burst.
        """
        parts: list[tuple[int, bytes]] = []
        size, ended = 0, False
        item = self._queue.get()
        while True:
            if item is None:
                ended = True
                break
            parts.append(item)
            size += len(item[1])
            if size >= COALESCE_BYTES:
                break
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
        with self._counts_lock:
            self._counts["queued_bytes"] -= size
        return parts, ended

    def _decode_loop(self, decoder: Decoder, sink: EventSink) -> None:
        aligner = ChunkAligner()
        ended = False
        while not ended:
            parts, ended = self._next_batch()
            pieces = [aligner.push(offset, data) for offset, data in parts]
            chunk = pieces[0] if len(pieces) == 1 else b"".join(pieces)
            with self._counts_lock:
                self._counts["stream_gaps"] = aligner.gaps
                self._counts["skipped_bytes"] = aligner.skipped_bytes
            if not chunk:
                continue
            try:
                events, triggers = decoder.decode(chunk)
            except DarkreadError as exc:
                log.warning("undecodable event data skipped: %s", exc)
                with self._counts_lock:
                    self._counts["decode_errors"] += 1
                decoder = self._decoder_factory()
                continue
            with self._counts_lock:
                self._counts["events"] += len(events)
                self._counts["triggers"] += len(triggers)
            if len(events) == 0:
                continue
            try:
                sink(events)
            except Exception:
                log.exception("event sink raised; chunk of %d events lost", len(events))
                with self._counts_lock:
                    self._counts["sink_errors"] += 1

    # --- settings -----------------------------------------------------------------------------

    def _require_device(self) -> Evk4Device:
        if self._device is None:
            raise DeviceError("camera is not open; call open() first")
        return self._device

    def set_biases(self, **offsets: int) -> None:
        """Set bias offsets from factory (diff_on, diff_off, fo, hpf, refr); applied now if open."""
        check_bias_offsets(offsets)
        with self._config_lock:
            self._bias_offsets.update(offsets)
            if self._device is not None:
                self._write_biases(offsets)

    def _write_biases(self, offsets: dict[str, int]) -> None:
        device = self._require_device()
        for name, offset in offsets.items():
            spec = regs.BIASES[name]
            rlo, rhi = spec.recommended
            if not rlo <= offset <= rhi:
                log.warning("bias %s offset %d is outside the recommended range [%d, %d]", name, offset, rlo, rhi)
            value = self._factory_biases[name] + offset
            if not 0 <= value <= regs.BIAS_VALUE_MASK:
                log.warning("bias %s = factory %d + %d clipped to [0, 255]", name, self._factory_biases[name], offset)
                value = min(max(value, 0), regs.BIAS_VALUE_MASK)
            device.write_register(spec.addr, regs.bias_write_value(value))

    @property
    def biases(self) -> dict[str, int]:
        """Current offsets from factory for every settable bias."""
        return {name: self._bias_offsets.get(name, 0) for name in regs.BIASES}

    def set_erc(self, rate_ev_s: float | None) -> None:
        """Cap the sensor's output at ``rate_ev_s`` events/s (``None`` turns the controller off)."""
        sequence = regs.erc_sequence(rate_ev_s)  # validates before anything is stored
        with self._config_lock:
            self._erc_rate = rate_ev_s
            if self._device is not None:
                self._device.apply(sequence)

    def set_roi(self, x0: int, y0: int, width: int, height: int) -> None:
        """Single-window analog ROI: pixels outside are never read out (less USB, less power).

        The full sensor size restores the full frame. With ``roi_follow`` the window is padded
        and only rewritten when the requested one leaves it.
        """
        regs.roi_window_words(x0, y0, width, height)  # ValueError when outside the sensor
        requested = (x0, y0, width, height)
        with self._config_lock:
            if self.roi_follow and requested != (0, 0, regs.WIDTH, regs.HEIGHT):
                target = follow_window(requested, self._roi, ROI_FOLLOW_MARGIN_PX, (regs.WIDTH, regs.HEIGHT))
                if target is None:
                    return
            else:
                target = requested
            if self._device is None:
                self._roi = None if target == (0, 0, regs.WIDTH, regs.HEIGHT) else target
                return
            self._program_roi(target)

    def _program_roi(self, window: tuple[int, int, int, int]) -> None:
        full = window == (0, 0, regs.WIDTH, regs.HEIGHT)
        if (None if full else window) == self._roi:
            return
        device = self._require_device()
        if full:
            device.apply(regs.ROI_DISABLE)
            self._roi = None
        else:
            device.apply(regs.roi_window_sequence(*window))
            for _ in range(ROI_POLL_ATTEMPTS):
                if device.read_register(regs.REG_ROI_WIN_CTRL) & regs.ROI_WIN_DONE:
                    break
            else:
                raise DeviceError(f"sensor did not latch ROI window {window} after {ROI_POLL_ATTEMPTS} polls")
            device.apply(regs.ROI_ENABLE)
            self._roi = window
        with self._counts_lock:
            self._counts["roi_writes"] += 1

    @property
    def roi(self) -> tuple[int, int, int, int]:
        """The window the sensor reads out (x0, y0, width, height)."""
        return self._roi or (0, 0, regs.WIDTH, regs.HEIGHT)

    @property
    def error(self) -> DarkreadError | None:
        """Why the drain thread stopped on its own (camera unplugged, USB error), if it did."""
        return self._reader_error

    @property
    def stats(self) -> dict[str, float]:
        """Counters of the current (or last) run; ``*_s`` in seconds, rates per second."""
        with self._counts_lock:
            counts = {k: float(v) for k, v in self._counts.items()}
        end = self._stopped_at or time.monotonic()
        elapsed = end - self._started_at if self._started_at is not None else 0.0
        counts["running"] = float(self.is_running)
        counts["elapsed_s"] = elapsed
        counts["event_rate_ev_s"] = counts["events"] / elapsed if elapsed > 0 else 0.0
        counts["usb_mb_s"] = counts["bytes_read"] / elapsed / 1e6 if elapsed > 0 else 0.0
        counts["reader_failed"] = float(self._reader_error is not None)
        return counts
