"""``darkread camera probe|record``: check the USB event camera and record RAW files from it.

Light module: pyusb and numpy load inside the handlers, so the command list never needs them.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

CAMERA_HELP = """\
The Prophesee EVK4 / EVK3 HD event camera (IMX636) on USB.

  darkread camera probe                      which cameras are attached, firmware, sensor, access
  darkread camera record out.raw -s 10       10 s of events to a RAW file OpenEB can read

Linux needs the udev rule edge/systemd/99-darkread-evk4.rules for access without root.
--fake RAW runs either command against an in-process fake camera serving that recording,
for demos and checks without hardware.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    camera = subparsers.add_parser(
        "camera", help="the USB event camera: probe it, record RAW files",
        description=CAMERA_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    commands = camera.add_subparsers(dest="camera_command", metavar="COMMAND")
    probe = commands.add_parser("probe", help="list attached cameras with serial, firmware and sensor")
    probe.add_argument("--fake", metavar="RAW", help="probe an in-process fake camera instead of USB")
    probe.set_defaults(func=_probe)
    record = commands.add_parser(
        "record", help="record events to a Prophesee RAW (EVT3) file",
        description="Record the camera's EVT3 stream, byte for byte, to a RAW file with an OpenEB header.",
    )  # fmt: skip
    record.add_argument("output", metavar="OUT.raw", help="file to write (overwritten)")
    record.add_argument("-s", "--seconds", type=float, default=10.0, help="how long to record (default 10)")
    record.add_argument("--serial", help="camera serial (default: the first camera found)")
    record.add_argument(
        "--bias", action="append", default=[], metavar="NAME=OFFSET",
        help="bias offset from factory, repeatable: diff_on, diff_off, fo, hpf, refr (e.g. --bias diff_on=20)",
    )  # fmt: skip
    record.add_argument("--erc", default="20e6", metavar="EV_S|off", help="event rate cap in events/s (default 20e6)")
    record.add_argument("--roi", metavar="X0,Y0,W,H", help="read out only this window of the sensor")
    record.add_argument("--fake", metavar="RAW", help="record from an in-process fake camera serving this file")
    record.set_defaults(func=_record)
    camera.set_defaults(func=lambda args: camera.print_help() or 2)


def parse_biases(items: list[str]) -> dict[str, int]:
    """``["diff_on=20", "refr=-5"]`` → ``{"diff_on": 20, "refr": -5}`` (ValueError on bad syntax)."""
    biases: dict[str, int] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            biases[name.strip()] = int(value)
        except ValueError:
            sep = ""
        if not sep:
            raise ValueError(f"--bias {item!r}: expected NAME=OFFSET with an integer offset, e.g. diff_on=20")
    return biases


def parse_erc(text: str) -> float | None:
    if text.lower() in {"off", "none", "0"}:
        return None
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"--erc {text!r}: expected events per second (e.g. 20e6) or 'off'") from None


def parse_roi(text: str | None) -> tuple[int, int, int, int] | None:
    if not text:
        return None
    parts = text.split(",")
    try:
        x0, y0, width, height = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"--roi {text!r}: expected X0,Y0,WIDTH,HEIGHT in pixels") from None
    return x0, y0, width, height


def _fake_backend(raw: str | None) -> tuple[Any, Any]:
    """(pyusb backend, fake board) for --fake, or (None, None) for real USB."""
    if raw is None:
        return None, None
    from darkread.edge.sources.evk4.fake import FakeEvk4, FakeUsbBackend

    path = Path(raw)
    if not path.is_file():
        raise FileNotFoundError(f"--fake {raw}: no such RAW file")
    fake = FakeEvk4.from_raw(path)
    return FakeUsbBackend([fake]), fake


def _probe(args: argparse.Namespace) -> int:
    from darkread.edge.errors import DeviceError
    from darkread.edge.sources.evk4 import registers as regs
    from darkread.edge.sources.evk4.device import Evk4Device, describe_ids, find_candidates
    from darkread.edge.sources.evk4.treuzell import format_version

    backend, _ = _fake_backend(args.fake)
    candidates = find_candidates(backend)
    if not candidates:
        print(f"no camera found (searched {describe_ids()})")
        return 1
    failures = 0
    for dev in candidates:
        where = f"{dev.idVendor:04x}:{dev.idProduct:04x} bus {dev.bus} address {dev.address}"
        device = Evk4Device(dev)
        try:
            device.claim()
            sensor_id = device.read_register(regs.REG_SENSOR_ID)
            sensor = "IMX636" if sensor_id == regs.IMX636_SENSOR_ID else f"unsupported sensor 0x{sensor_id:08X}"
            print(f"{where}: serial {device.serial}, firmware {format_version(device.release_version)}, {sensor}")
        except DeviceError as exc:
            failures += 1
            print(f"{where}: {exc}")
        finally:
            device.release()
    return 1 if failures else 0


def _record(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from darkread.edge.io.raw_header import format_raw_header
    from darkread.edge.sources.evk4 import registers as regs
    from darkread.edge.sources.evk4.camera import Evk4Camera

    if args.seconds <= 0:
        raise ValueError(f"--seconds must be positive, got {args.seconds}")
    biases, erc, roi = parse_biases(args.bias), parse_erc(args.erc), parse_roi(args.roi)
    backend, fake = _fake_backend(args.fake)
    settle = time.sleep if fake is None else (lambda seconds: None)  # a fake board needs no settling
    camera = Evk4Camera(serial=args.serial, biases=biases, erc_rate_ev_s=erc, backend=backend, sleep=settle)
    if roi is not None:
        camera.set_roi(*roi)
    output = Path(args.output)
    with camera, output.open("wb") as out:
        serial = camera.device_serial
        header = {"serial_number": serial, "plugin_name": "hal_plugin_imx636_evk4", "sensor_generation": "4.2",
                  "date": time.strftime("%Y-%m-%d %H:%M:%S")}  # fmt: skip
        out.write(format_raw_header(regs.WIDTH, regs.HEIGHT, "EVT3", header))
        camera.start(lambda events: None, raw_sink=out.write)
        started = time.monotonic()
        progress = "{desc}: {n:.1f}/{total:.1f} s |{bar}| {postfix}"
        with tqdm(total=round(args.seconds, 1), desc=f"recording {output.name}", bar_format=progress) as bar:
            while (elapsed := time.monotonic() - started) < args.seconds and camera.error is None:
                if fake is not None and fake.exhausted:
                    break
                time.sleep(0.1)
                bar.n = round(min(elapsed, args.seconds), 1)
                bar.set_postfix(ev_s=f"{camera.stats['event_rate_ev_s']:.3g}", refresh=True)
        camera.stop()
        stats = camera.stats
    if camera.error is not None:
        raise camera.error
    print(
        f"{output}: {stats['bytes_read'] / 1e6:.1f} MB, {stats['events']:.0f} events in {stats['elapsed_s']:.1f} s "
        f"({stats['event_rate_ev_s']:.3g} ev/s), {stats['dropped_bytes']:.0f} bytes dropped before decoding"
    )
    return 0
