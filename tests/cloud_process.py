"""``darkread cloud serve`` as a real subprocess on 127.0.0.1 (it can be SIGKILLed), and a free port."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

API_KEY = "integration-key"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class CloudProcess:
    """One cloud instance: SQLite in ``data_dir``, or the PostgreSQL database at ``database_url``."""

    def __init__(self, data_dir: Path, port: int | None = None, *, database_url: str | None = None,
                 api_key: str = API_KEY, log_path: Path | None = None, env: dict[str, str] | None = None) -> None:  # fmt: skip
        self.data_dir, self.port = data_dir, port or free_port()
        self.database_url, self.api_key = database_url, api_key
        self.log_path = log_path
        self.env = env or {}  # more DARKREAD_* settings
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/v1/stream"

    def start(self, timeout_s: float = 30) -> None:
        self.launch()
        self.wait_ready(timeout_s)

    def launch(self) -> None:
        """Start the process without waiting (start several instances side by side)."""
        # a loaded machine stitches slowly: an ask waits for every stored frame, as the tests check
        env = dict(os.environ, DARKREAD_API_KEY=self.api_key, DARKREAD_ASK_CATCH_UP_S="60", **self.env)
        if self.database_url:
            env["DARKREAD_DATABASE_URL"] = self.database_url
        log = open(self.log_path, "ab") if self.log_path else subprocess.DEVNULL  # closed below
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "darkread", "-q", "cloud", "serve", "--host", "127.0.0.1",
                 "--port", str(self.port), "--data-dir", str(self.data_dir)],
                env=env, stdout=log, stderr=log,
            )  # fmt: skip
        finally:
            if log is not subprocess.DEVNULL:
                log.close()  # the child has its own copy

    def wait_ready(self, timeout_s: float = 30) -> None:
        self._wait_for("/healthz", timeout_s, answer_s=0.5, pause_s=0.1, failure="did not come up")

    def wait_warm(self, timeout_s: float = 60) -> None:
        """Until /readyz says every dependency is ready: the OCR models load in the background after
        /healthz answers, and a test that reads the process's memory must not count them."""
        self._wait_for("/readyz", timeout_s, answer_s=5.0, pause_s=0.2, failure="not ready (/readyz)")

    def _wait_for(self, path: str, timeout_s: float, *, answer_s: float, pause_s: float, failure: str) -> None:
        """Until ``path`` answers 2xx, the process still running."""
        assert self.process is not None  # launch() first
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"cloud exited with {self.process.returncode}")
            try:
                with urllib.request.urlopen(f"{self.url}{path}", timeout=answer_s):
                    return
            except OSError:
                time.sleep(pause_s)
        raise RuntimeError(f"cloud {failure} within {timeout_s:g} s")

    def memory_mb(self) -> tuple[float, float]:
        """(resident set now, its peak so far) in MB, from /proc."""
        assert self.process is not None  # launch() first
        fields = dict(line.split(":", 1) for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines())
        return int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024

    def settled_memory_mb(self, timeout_s: float = 30, within_mb: float = 2.0) -> float:
        """The resident set once it holds still (two readings 1 s apart within ``within_mb``): after
        /readyz the OCR engine still allocates for a few seconds, which no request should be blamed for."""
        deadline = time.monotonic() + timeout_s
        last = self.memory_mb()[0]
        while time.monotonic() < deadline:
            time.sleep(1.0)
            now = self.memory_mb()[0]
            if abs(now - last) <= within_mb:
                return now
            last = now
        raise RuntimeError(f"cloud memory did not settle within {timeout_s:g} s (last {last:.0f} MB)")

    def kill(self) -> None:
        """SIGKILL: no shutdown, no flush, connections cut."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
            self.process.wait(5)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()
