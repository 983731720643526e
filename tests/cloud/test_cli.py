"""``darkread cloud serve`` as users start it: a subprocess answering /healthz and /readyz."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

from darkread.cli import build_parser


def test_serve_options_parse() -> None:
    args = build_parser().parse_args(["cloud", "serve", "--port", "9000", "--data-dir", "/tmp/x", "--ocr", "openai"])
    assert (args.port, args.data_dir, args.ocr, args.host) == (9000, Path("/tmp/x"), "openai", "127.0.0.1")


def test_serve_starts_and_is_ready(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    env = {**os.environ, "DARKREAD_API_KEY": "k"}
    process = subprocess.Popen(
        [sys.executable, "-m", "darkread", "-q", "cloud", "serve", "--port", str(port), "--data-dir", str(tmp_path / "d")],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/readyz", timeout=30) as response:
                    ready = json.loads(response.read())
                break
            except OSError:
                if process.poll() is not None or time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        assert ready == {"status": "ready", "checks": {"store": True, "ocr:rapidocr+lexicon": True}}
        assert (tmp_path / "d" / "darkread.sqlite3").is_file()
    finally:
        process.terminate()
        _, stderr = process.communicate(timeout=20)
    # uvicorn shuts down gracefully on SIGTERM, then re-raises the signal.
    assert process.returncode in (0, -15), stderr.decode()[-2000:]
    assert b"Traceback" not in stderr


def test_a_broken_line_confidence_model_is_one_line_before_the_server_starts(tmp_path: Path) -> None:
    """A model file that is truncated or from elsewhere: one line naming it and exit 1, no traceback,
    and the data directory left free for the next start."""
    shipped = json.loads((Path(__file__).parents[2] / "cloud" / "data" / "line_confidence.json").read_text())
    broken = {"truncated.json": json.dumps(shipped)[:200], "wrong.json": json.dumps({**shipped, "shed_thresholds": {"three": 0.5}}),
              "short.json": json.dumps({**shipped, "weights": shipped["weights"][:3]})}
    for name, text in broken.items():
        (tmp_path / name).write_text(text)
        done = subprocess.run(
            [sys.executable, "-m", "darkread", "-q", "cloud", "serve", "--port", "1", "--data-dir", str(tmp_path / "d")],
            env={**os.environ, "DARKREAD_API_KEY": "k", "DARKREAD_LINE_CONFIDENCE_MODEL": str(tmp_path / name)},
            capture_output=True, text=True, timeout=60,
        )
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 1 and len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
        assert str(tmp_path / name) in lines[0] and "not a line-confidence model" in lines[0]
