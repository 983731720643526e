"""The edge on a wearable's CPU budget: a paced replay (speed 1) in a CPU quota, and what it says.

A wearable gives the edge a fraction of one small core. :class:`CpuQuota` makes a child control
group with CFS bandwidth control, ``cpu.max`` on cgroup v2 or, where the CPU controller is still
on a cgroup v1 hierarchy (as in many containers), ``cpu.cfs_quota_us`` / ``cpu.cfs_period_us``:
the same kernel mechanism. :func:`run_under_quota` starts ``darkread edge run --replay ... --speed 1``
as its own process against a loopback acknowledging server (``ack_server.AckServer``), moves it
into the quota once it is ready (the model loaded, the decoder compiled: what a wearable does once
at boot), samples its resident memory while it runs and reads its final metrics line: frames
lost, view latency, the step lag, what it shed.

``darkread quota`` prints the figures for a list of quotas (docs/edge_cpu.md).
"""

from __future__ import annotations

import argparse
import itertools
import os
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from darkread.core.paths import SAMPLE_RECORDING
from darkread.lab.bench import cpu_seconds
from darkread.lab.bench.ack_server import AckServer

CGROUP_ROOTS = (Path("/sys/fs/cgroup"), Path("/sys/fs/cgroup/unified"))  # cgroup v2: alone, or beside v1
CGROUP_V1_CPU = Path("/sys/fs/cgroup/cpu")
PERIOD_US = 100_000
_names = itertools.count()


class QuotaUnavailable(RuntimeError):
    """No writable CPU controller here (no cgroup v2 with ``cpu``, no cgroup v1 ``cpu`` hierarchy)."""


def _v2_root() -> Path | None:
    for root in CGROUP_ROOTS:
        controllers = root / "cgroup.controllers"
        if controllers.is_file() and "cpu" in controllers.read_text().split() and os.access(root, os.W_OK):
            return root
    return None


def quota_backend() -> tuple[str, Path]:
    """("v2", root) or ("v1", the cpu hierarchy), whichever can take a child group; QuotaUnavailable else."""
    root = _v2_root()
    if root is not None:
        return "v2", root
    if (CGROUP_V1_CPU / "cpu.cfs_quota_us").is_file() and os.access(CGROUP_V1_CPU, os.W_OK):
        return "v1", CGROUP_V1_CPU
    raise QuotaUnavailable("no writable cgroup CPU controller (cgroup v2 cpu.max or v1 cpu.cfs_quota_us); run as root "
                           "on a host or a privileged container")


class CpuQuota:
    """A child control group limited to ``share`` of one core; ``add(pid)`` moves a process in.
    A context manager: on exit its processes go back to the parent and the group is removed."""

    def __init__(self, share: float) -> None:
        if not 0 < share <= 64:
            raise ValueError(f"a CPU share is above 0 (of one core), not {share}")
        self.share = share
        self.kind, self.parent = quota_backend()
        self.path = self.parent / f"darkread-quota-{os.getpid()}-{next(_names)}"

    def __enter__(self) -> CpuQuota:
        if self.kind == "v2":
            control = self.parent / "cgroup.subtree_control"
            if "cpu" not in control.read_text().split():
                control.write_text("+cpu")
        self.path.mkdir()
        quota_us = max(1000, int(self.share * PERIOD_US))
        if self.kind == "v2":
            (self.path / "cpu.max").write_text(f"{quota_us} {PERIOD_US}")
        else:
            (self.path / "cpu.cfs_period_us").write_text(str(PERIOD_US))
            (self.path / "cpu.cfs_quota_us").write_text(str(quota_us))
        return self

    def add(self, pid: int) -> None:
        (self.path / "cgroup.procs").write_text(str(pid))

    def throttled_s(self) -> float:
        """How long the group's processes waited for quota so far (the kernel's cpu.stat)."""
        stat = dict(line.split() for line in (self.path / "cpu.stat").read_text().splitlines() if line.strip())
        if "throttled_usec" in stat:
            return int(stat["throttled_usec"]) / 1e6
        return int(stat.get("throttled_time", 0)) / 1e9

    def __exit__(self, *exc: object) -> None:
        procs = self.path / "cgroup.procs"
        for pid in procs.read_text().split() if procs.exists() else []:
            try:
                (self.parent / "cgroup.procs").write_text(pid)
            except OSError:  # it exited meanwhile
                pass
        for _ in range(50):
            try:
                self.path.rmdir()
                return
            except OSError:  # the last process is still leaving
                time.sleep(0.05)


@dataclass(frozen=True)
class QuotaRun:
    share: float  # of one core
    cgroup: str  # v2 or v1
    exit_code: int
    wall_s: float
    views: int  # acknowledged by the loopback server
    frames_lost: int  # windows skipped (every-window) + messages the spool evicted + submitted but never acknowledged
    view_latency_p99_ms: float  # fixation end to its view on the wire
    step_lag_p99_ms: float
    shed_level: int  # at the end
    views_capped: int
    views_shed: int  # fixations given no view (level 3: the last view covered their window)
    shed_changes: int
    rss_max_mb: float
    rss_growth_mb: float  # the last sample against the first one in the quota
    throttled_s: float
    cpu_s: float  # the edge's CPU time in the quota (sampled every 0.1 s until it exits)
    log_tail: str


FINAL = re.compile(r"final: (?P<line>.*)")
FIELDS = {
    "skips": r"skips (\d+)",
    "lost": r"\(lost (\d+)\)",
    "wire_p99": r"wire p50 [\d.]+ p99 ([\d.]+) ms",
    "lag_p99": r"step lag p99 (\d+) ms",
    "level": r"shedding level (\d+)",
    "capped": r"views capped (\d+)",
    "views_shed": r"views capped \d+, shed (\d+)",
}


def _rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def _cpu_s(pid: int) -> float | None:
    """The process's CPU time so far (``cpu_seconds``), None once it is gone."""
    try:
        return cpu_seconds(pid)
    except (OSError, IndexError):
        return None


def run_under_quota(share: float, recording: Path = SAMPLE_RECORDING, *, timeout_s: float = 120.0,
                    extra_args: tuple[str, ...] = ()) -> QuotaRun:
    """One paced replay of ``recording`` by ``darkread edge run`` in ``share`` of one core."""
    server = AckServer()
    try:
        with CpuQuota(share) as quota:
            cmd = [sys.executable, "-m", "darkread", "edge", "run", "--replay", str(recording), "--speed", "1",
                   "--cloud", server.url, "--spool", ":memory:", "--session", f"quota-{os.getpid()}", "--drain-timeout", "20",
                   *extra_args]
            env = {**os.environ, "DARKREAD_EDGE_METRICS_LOG_EVERY_S": "3600", "DARKREAD_EDGE_UPLINK_DEVICE_ID": "quota"}
            started = time.monotonic()
            proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env)
            lines: list[str] = []
            rss: list[float] = []
            cpu: list[float] = []
            ready = threading.Event()

            def read_stderr() -> None:
                assert proc.stderr is not None
                for line in proc.stderr:
                    lines.append(line.rstrip("\n"))
                    if line.startswith("streaming session"):  # built and warm: the replay starts now
                        quota.add(proc.pid)
                        ready.set()

            reader = threading.Thread(target=read_stderr, daemon=True)
            reader.start()
            while proc.poll() is None and time.monotonic() - started < timeout_s:
                if ready.is_set():
                    value = _rss_mb(proc.pid)
                    if value is not None:
                        rss.append(value)
                    used = _cpu_s(proc.pid)
                    if used is not None:
                        cpu.append(used)
                time.sleep(0.1)
            if proc.poll() is None:
                proc.kill()
            code = proc.wait()
            reader.join(5)
            if proc.stderr is not None:
                proc.stderr.close()
            wall = time.monotonic() - started
            throttled = quota.throttled_s()
        acked = len(server.stored.get(f"quota-{os.getpid()}", []))
    finally:
        server.close()
    final = next((m.group("line") for m in map(FINAL.search, reversed(lines)) if m), "")
    found = {key: re.search(pattern, final) for key, pattern in FIELDS.items()}

    def number(key: str) -> float:
        match = found[key]
        return float(match.group(1)) if match is not None and match.groups() else float("nan")

    lost = int(number("skips")) + int(number("lost")) if final else -1
    return QuotaRun(
        share=share, cgroup=quota.kind, exit_code=code, wall_s=wall, views=acked, frames_lost=lost,
        view_latency_p99_ms=number("wire_p99"), step_lag_p99_ms=number("lag_p99"), shed_level=int(number("level")) if final else -1,
        views_capped=int(number("capped")) if final else -1, views_shed=int(number("views_shed")) if final else -1,
        shed_changes=sum("falling behind" in line for line in lines),
        rss_max_mb=max(rss, default=float("nan")), rss_growth_mb=(rss[-1] - rss[0]) if len(rss) > 1 else 0.0,
        throttled_s=throttled, cpu_s=(cpu[-1] - cpu[0]) if len(cpu) > 1 else float("nan"), log_tail="\n".join(lines[-6:]),
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", nargs="?", default=str(SAMPLE_RECORDING), help="recording to replay (default: the sample)")
    parser.add_argument("--quota", type=float, nargs="+", default=[0.25, 0.10], metavar="SHARE",
                        help="shares of one core to run under (default 0.25 0.10)")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("quota", help="the edge's paced replay in CPU quotas (lab): frames lost, view latency, RSS",
                                   description="Replay a recording at real time through `darkread edge run` inside a CPU "
                                               "quota (a cgroup; needs root) and print what it lost, its view latency, "
                                               "what it shed and its memory.")
    add_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """``darkread quota``: one paced replay per quota, its figures as a table."""
    recording = Path(args.recording)
    if not (recording / "events.raw").is_file() and not recording.is_file():
        raise ValueError(f"{recording}: no recording (a folder with events.raw, or a .raw file)")
    duration = _duration_s(recording)
    # the wall clock beside the recording's length: a replay in too small a quota is slowed (its reader
    # shares the quota) rather than losing events, so "nothing lost" means real time only when they agree
    print(f"{'quota':>6} {'views':>6} {'lost':>5} {'view p99 ms':>12} {'step lag p99 ms':>16} {'level':>5} "
          f"{'capped':>7} {'no view':>7} {'RSS max MB':>11} {'RSS growth MB':>14} {'throttled s':>12} {'CPU s':>6} {f'wall s ({duration:g} s)':>16}")
    for share in args.quota:
        r = run_under_quota(share, recording, timeout_s=max(120.0, 10 * duration))
        print(f"{share:>6.0%} {r.views:>6} {r.frames_lost:>5} {r.view_latency_p99_ms:>12.1f} {r.step_lag_p99_ms:>16.0f} "
              f"{r.shed_level:>5} {r.views_capped:>7} {r.views_shed:>7} {r.rss_max_mb:>11.0f} {r.rss_growth_mb:>14.1f} "
              f"{r.throttled_s:>12.1f} {r.cpu_s:>6.2f}"
              f" {r.wall_s:>16.1f}  ({r.cgroup}, exit {r.exit_code})", flush=True)
        if r.exit_code != 0:
            print(r.log_tail, file=sys.stderr)
    return 0


def _duration_s(recording: Path) -> float:
    from darkread.edge.io.recording import open_recording  # CLI handler

    meta = open_recording(recording).meta if recording.is_dir() else {}
    return float(meta.get("duration_s", 60.0))

