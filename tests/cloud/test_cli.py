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
