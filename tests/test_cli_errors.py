"""Bad input to the real ``darkread`` command: one line on stderr and a non-zero exit, never a traceback."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from darkread.cli import EXIT_ERROR, EXIT_INTERNAL, EXIT_USAGE, error_line
from darkread.core.errors import DarkreadError
from darkread.edge.errors import CalibrationError

SAMPLE = Path(__file__).resolve().parents[1] / "darkread" / "data" / "sample_recording"


def _darkread(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """The installed console script beside this interpreter (what a user types); ``-q`` keeps the
    progress log off stderr, so the error line is all that is left there."""
    command = Path(sys.executable).with_name("darkread")
    prefix = [str(command)] if command.is_file() else [sys.executable, "-m", "darkread"]
    return subprocess.run([*prefix, "-q", *argv], capture_output=True, text=True, timeout=timeout, check=False)


def _assert_one_line(result: subprocess.CompletedProcess[str], *, mentions: str) -> None:
    assert result.returncode == EXIT_ERROR, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("darkread: error: ") and mentions in lines[0], lines[0]
    assert "Traceback" not in result.stderr


def _broken_copy(tmp_path: Path, name: str, content: bytes) -> Path:
    recording = tmp_path / "recording"
    shutil.copytree(SAMPLE, recording)
    (recording / name).write_bytes(content)
    return recording


def test_inspect_a_missing_path(tmp_path: Path) -> None:
    _assert_one_line(_darkread("inspect", str(tmp_path / "nowhere")), mentions="nowhere")


def test_inspect_a_file_that_is_not_raw(tmp_path: Path) -> None:
    path = tmp_path / "garbage.raw"
    path.write_bytes(b"\x00\xff not a prophesee file " * 40)
    _assert_one_line(_darkread("inspect", str(path)), mentions="garbage.raw")


def test_read_a_recording_whose_calibration_is_not_json(tmp_path: Path) -> None:
    recording = _broken_copy(tmp_path, "calibration.json", b'{"intrinsics": [1, 2,')
    _assert_one_line(_darkread("read", str(recording)), mentions="calibration.json")


def test_read_a_recording_whose_gaze_csv_is_not_text(tmp_path: Path) -> None:
    recording = _broken_copy(tmp_path, "general_eye_gaze.csv", b"\xff\xfe\x00garbage\x00\n\x81\x82")
    _assert_one_line(_darkread("read", str(recording)), mentions="general_eye_gaze.csv")


def test_read_has_no_research_flags() -> None:
    result = _darkread("read", "--demo", "--true-motion")
    assert result.returncode == 2 and "unrecognized arguments: --true-motion" in result.stderr


def test_read_a_bare_raw_file_names_the_options_it_needs(tmp_path: Path) -> None:
    raw = tmp_path / "events.raw"
    shutil.copyfile(SAMPLE / "events.raw", raw)
    result = _darkread("read", str(raw))
    _assert_one_line(result, mentions="--gaze-csv CSV")
    assert "--calibration JSON" in result.stderr


def _assert_usage_error(result: subprocess.CompletedProcess[str], *, command: str, mentions: str) -> None:
    """argparse's way: the command's own usage, then one error line naming what to give."""
    assert result.returncode == EXIT_USAGE, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith(f"usage: {command} "), result.stderr
    assert lines[-1].startswith(f"{command}: error: ") and mentions in lines[-1], lines[-1]
    assert "Traceback" not in result.stderr


def test_a_replay_speed_that_is_not_a_number_names_the_option_and_its_values() -> None:
    result = _darkread("edge", "run", "--speed", "fast")
    _assert_usage_error(result, command="darkread edge run", mentions="argument --speed:")
    assert "'max'" in result.stderr and "'fast'" in result.stderr


@pytest.mark.parametrize(
    ("argv", "command", "mentions"),
    [
        (("read", "--demo", "--sya"), "darkread read", "--sya (did you mean --say?)"),
        (("cloud", "serve", "--prot", "8001"), "darkread cloud serve", "--prot 8001 (did you mean --port?)"),
        (("edge", "run", "--replay", "x", "--zzz"), "darkread edge run", "--zzz (see darkread edge run --help)"),
    ],
)
def test_a_mistyped_option_prints_the_usage_of_its_own_command(argv: tuple[str, ...], command: str, mentions: str) -> None:
    _assert_usage_error(_darkread(*argv), command=command, mentions=f"unrecognized arguments: {mentions}")


def test_synth_into_a_path_under_a_regular_file(tmp_path: Path) -> None:
    """An OSError other than FileNotFoundError (here NotADirectoryError) is bad input too."""
    (tmp_path / "afile").write_text("")
    _assert_one_line(_darkread("synth", "recording", str(tmp_path / "afile" / "out"), "--seconds", "0.2"), mentions="afile")


def test_eval_a_suite_that_does_not_exist(tmp_path: Path) -> None:
    _assert_one_line(_darkread("eval", "run", str(tmp_path / "no_suite")), mentions="no_suite")


def test_every_darkread_error_is_a_user_error_and_anything_else_a_bug() -> None:
    assert issubclass(CalibrationError, DarkreadError)
    assert error_line(CalibrationError("bad\n  intrinsics")) == "darkread: error: bad intrinsics"
    assert error_line(FileNotFoundError(2, "No such file", "x.raw")).startswith("darkread: error: ")
    bug = error_line(RuntimeError("loop failed"))
    assert bug.startswith("darkread: internal error: RuntimeError: loop failed") and "\n" not in bug
    assert EXIT_INTERNAL != EXIT_ERROR


@pytest.mark.parametrize(
    "module",
    ["darkread.proto.errors", "darkread.cloud.errors", "darkread.edge.errors", "darkread.edge.sources.evk4.treuzell"],
)
def test_each_component_error_derives_from_the_one_base(module: str) -> None:
    import importlib
    import inspect

    classes = [c for _, c in inspect.getmembers(importlib.import_module(module), inspect.isclass) if issubclass(c, Exception)]
    assert classes
    assert all(issubclass(c, DarkreadError) for c in classes), [c for c in classes if not issubclass(c, DarkreadError)]


def test_the_drawn_tree_is_the_real_tree() -> None:
    """Every class in the diagram of ``darkread/core/errors.py`` exists and derives from the one drawn above it."""
    import importlib
    import re

    import darkread.core.errors

    modules = ["darkread.core.errors", "darkread.core.image_codec", "darkread.edge.errors", "darkread.edge.sources.evk4.treuzell",
               "darkread.proto.errors", "darkread.cloud.errors"]
    known = {name: obj for m in modules for name, obj in vars(importlib.import_module(m)).items() if isinstance(obj, type)}
    parents: list[tuple[int, type]] = []
    drawn = 0
    for line in (darkread.core.errors.__doc__ or "").splitlines():
        match = re.match(r"^(\s*[│ ]*(?:├── |└── )?)([A-Z]\w+Error)\b", line)
        if not match:
            continue
        depth, cls = len(match.group(1)), known[match.group(2)]
        while parents and parents[-1][0] >= depth:
            parents.pop()
        if parents:
            assert cls.__bases__[0] is parents[-1][1], f"{cls.__name__} is drawn under {parents[-1][1].__name__}"
        parents.append((depth, cls))
        drawn += 1
    assert drawn >= 20
