"""A real small filesystem for the spool's error paths: a tmpfs that can fill up or turn read-only.

Mounting needs root (CAP_SYS_ADMIN); elsewhere the tests that need it skip, saying so.
"""

from __future__ import annotations

import contextlib
import errno
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


class SmallDisk:
    """A mounted tmpfs of ``size_kb`` at ``path``."""

    def __init__(self, path: Path, size_kb: int) -> None:
        self.path, self.size_kb = path, size_kb
        self.filler = path / "filler"

    def fill(self, leave_kb: int = 0) -> None:
        """Write a filler file until only about ``leave_kb`` are free (0: the disk is full)."""
        with open(self.filler, "ab") as handle:
            chunk = b"\0" * 4096
            try:
                while self.free_kb() > leave_kb:
                    handle.write(chunk)
                    handle.flush()
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise

    def free_kb(self) -> int:
        stat = os.statvfs(self.path)
        return stat.f_bavail * stat.f_frsize // 1024

    def empty_filler(self) -> None:
        self.filler.unlink(missing_ok=True)

    def read_only(self) -> None:
        _mount("-o", "remount,ro", str(self.path))

    def writable(self) -> None:
        _mount("-o", "remount,rw", str(self.path))


def _mount(*args: str) -> None:
    subprocess.run(["mount", *args], check=True, capture_output=True, text=True, timeout=30)


@contextlib.contextmanager
def small_disk(path: Path, size_kb: int) -> Iterator[SmallDisk]:
    """Mount a tmpfs of ``size_kb`` at ``path`` for the block; skip the test when that is not allowed."""
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs (full or read-only disk) needs root")
    try:
        _mount("-t", "tmpfs", "-o", f"size={size_kb}k,mode=0755", "tmpfs", str(path))
    except (OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or exc
        pytest.skip(f"cannot mount a tmpfs here ({str(detail).strip()}): no full or read-only disk to test with")
    try:
        yield SmallDisk(path, size_kb)
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, timeout=30, check=False)
