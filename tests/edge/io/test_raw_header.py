"""RAW header parsing: current, legacy and broken headers."""

from __future__ import annotations

from pathlib import Path

import pytest

from darkread.edge.errors import RawFormatError
from darkread.edge.io.raw_header import format_raw_header, parse_raw_header, read_raw_header

MODERN = (
    b"% camera_integrator_name Prophesee\n% date 2024-10-20 15:40:51\n% evt 3.0\n"
    b"% format EVT3;height=720;width=1280\n% geometry 1280x720\n% system_ID 49\n% end\n"
)


def test_modern_header_gives_format_size_fields_and_offset() -> None:
    header = parse_raw_header(MODERN + b"\x00\x80", path="x.raw")
    assert (header.format, header.width, header.height) == ("EVT3", 1280, 720)
    assert header.fields["date"] == "2024-10-20 15:40:51"
    assert header.fields["system_ID"] == "49"
    assert "end" not in header.fields
    assert header.data_offset == len(MODERN)


def test_header_without_end_stops_at_first_binary_line() -> None:
    data = b"% Date 2020-09-25 07:48:29\n% evt 3.0\n% system_ID 48\n" + bytes([0x2D, 0x8B, 0x00, 0x00])
    header = parse_raw_header(data)
    assert (header.format, header.width, header.height) == ("EVT3", 1280, 720)
    assert header.data_offset == len(data) - 4


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (b"% system_ID 21\n", ("EVT2", 640, 480)),
        (b"% evt 2.0\n% system_ID 21\n", ("EVT2", 640, 480)),
        (b"% system_ID 50\n", ("EVT3", 1280, 720)),
        (b"% evt 3.0\n% geometry 640x480\n", ("EVT3", 640, 480)),
        (b"% format EVT2;height=480;width=640\n", ("EVT2", 640, 480)),
    ],
)
def test_format_and_geometry_are_inferred_like_openeb(lines: bytes, expected: tuple[str, int, int]) -> None:
    header = parse_raw_header(lines + b"% end\n")
    assert (header.format, header.width, header.height) == expected


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        (b"% format EVT21;height=720;width=1280\n", "EVT21"),
        (b"% evt 2.1\n% geometry 1280x720\n", "not supported"),
        (b"% date 2024-01-01\n", "names no event format"),
        (b"% evt 3.0\n% system_ID 99\n", "no sensor size"),
        (b"% format EVT3;height=abc;width=1280\n", "not an integer"),
        (b"", "names no event format"),
    ],
)
def test_unusable_headers_raise_raw_format_error(lines: bytes, message: str) -> None:
    with pytest.raises(RawFormatError, match=message):
        parse_raw_header(lines + b"% end\n" if lines else b"", path="bad.raw")


def test_format_raw_header_round_trips_and_ends_with_end_line() -> None:
    text = format_raw_header(640, 480, "EVT2", {"serial_number": "00ab", "date": "2026-01-01 10:00:00"})
    assert text.endswith(b"% end\n")
    header = parse_raw_header(text + b"\x01\x02")
    assert (header.format, header.width, header.height, header.data_offset) == ("EVT2", 640, 480, len(text))
    assert header.fields["serial_number"] == "00ab"
    assert header.fields["date"] == "2026-01-01 10:00:00"


@pytest.mark.parametrize("bad", [{"a b": "c"}, {"k": "x\ny"}, {"end": "1"}])
def test_format_raw_header_rejects_lines_that_would_break_the_header(bad: dict[str, str]) -> None:
    with pytest.raises(ValueError):
        format_raw_header(1280, 720, extra=bad)


def test_read_raw_header_reads_long_headers_and_missing_files(tmp_path: Path) -> None:
    long_lines = "".join(f"% note_{i} {'x' * 100}\n" for i in range(200)).encode()
    path = tmp_path / "long.raw"
    path.write_bytes(long_lines + format_raw_header(1280, 720) + b"\x00\x80" * 10)
    header = read_raw_header(path)
    assert header.fields["note_199"] == "x" * 100
    assert header.data_offset == path.stat().st_size - 20
    with pytest.raises(FileNotFoundError):
        read_raw_header(tmp_path / "missing.raw")


def test_header_only_file_has_data_offset_at_end(tmp_path: Path) -> None:
    path = tmp_path / "empty.raw"
    path.write_bytes(format_raw_header(1280, 720))
    assert read_raw_header(path).data_offset == path.stat().st_size


@pytest.mark.shared
def test_real_file_headers(real_events_dir: Path) -> None:
    expected = {
        "gen41_hd_evt3__expelliarmus_evt3_sample.raw": ("EVT3", 1280, 720),
        "hd_evt3_trigger_erc__event_camera_codecs.raw": ("EVT3", 1280, 720),
        "vga_evt3_trigger__event_camera_py.raw": ("EVT3", 640, 480),
        "gen3_vga_evt2__expelliarmus_evt2_sample.raw": ("EVT2", 640, 480),
    }
    for name, fmt in expected.items():
        header = read_raw_header(real_events_dir / name)
        assert (header.format, header.width, header.height) == fmt, name
