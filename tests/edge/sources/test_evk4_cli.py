from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from factories import random_events

from darkread.cli import main
from darkread.edge.io.raw import read_raw, write_raw
from darkread.edge.sources.evk4.cli import parse_biases, parse_erc, parse_roi


@pytest.fixture
def raw_file(tmp_path: Path) -> Path:
    path = tmp_path / "in.raw"
    write_raw(path, random_events(20_000, t0=1000, rate_hz=2e6, seed=11))
    return path


def test_probe_reports_serial_firmware_and_sensor(raw_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["camera", "probe", "--fake", str(raw_file)]) == 0
    out = capsys.readouterr().out
    assert "04b4:00f5" in out and "serial 00050a2b" in out and "firmware 3.9.0" in out and "IMX636" in out


def test_record_writes_the_stream_byte_for_byte(raw_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_path = tmp_path / "out.raw"
    args = ["camera", "record", str(out_path), "--fake", str(raw_file), "-s", "20", "--bias", "diff_on=10", "--roi", "0,0,1280,720"]
    assert main(args) == 0
    recorded, original = read_raw(out_path), read_raw(raw_file)
    np.testing.assert_array_equal(recorded.events, original.events)
    assert recorded.header.fields["serial_number"] == "00050a2b"
    assert "20000 events" in capsys.readouterr().out


def test_record_rejects_bad_options(raw_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["camera", "record", str(tmp_path / "x.raw"), "--fake", str(raw_file), "--bias", "diff=3"]) == 1
    assert "reference of diff_on/diff_off" in capsys.readouterr().err


def test_option_parsers() -> None:
    assert parse_biases(["diff_on=20", "refr=-5"]) == {"diff_on": 20, "refr": -5}
    assert parse_erc("off") is None and parse_erc("1e6") == 1e6
    assert parse_roi("1,2,3,4") == (1, 2, 3, 4) and parse_roi(None) is None
    with pytest.raises(ValueError, match="NAME=OFFSET"):
        parse_biases(["diff_on"])
    with pytest.raises(ValueError, match="X0,Y0,WIDTH,HEIGHT"):
        parse_roi("1,2,3")
    with pytest.raises(ValueError, match="events per second"):
        parse_erc("fast")
