"""A real ``darkread edge run`` when things go wrong around it: its key in the URL, a read-only or
full spool disk, no cloud listening, a wrong key. Each run ends with one ``darkread: error:``
line saying what failed and an exit status naming it; the counts in the log agree with that line;
and what a run could not deliver is delivered, once, by the next start against a real cloud.

Each case prints ``| command | exit | the line | made / stored / still spooled after a restart |``
(run with ``-s`` for the table).
"""

from __future__ import annotations

import contextlib
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from cloud_process import API_KEY, free_port
from factories import sum_bins_model
from small_disk import small_disk

from .test_edge_to_cloud import Cloud

pytestmark = pytest.mark.slow

SPOOLED = re.compile(r"(\d+) messages? (?:stays? in the spool|(?:is|are) lost)")


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sum_bins_model(tmp_path_factory.mktemp("model") / "tiny.onnx")


def staying(n: int) -> str:
    """How the edge's last line says how many messages stay in the spool (one, or several)."""
    return "1 message stays in the spool" if n == 1 else f"{n} messages stay in the spool"


def spool_counts(spool: Path) -> tuple[int, int]:
    """(messages the spool ever numbered, messages still waiting in it); the file is closed after
    (an open database keeps its file system from being remounted read-only)."""
    with contextlib.closing(sqlite3.connect(spool / "spool.sqlite3")) as db:
        last = db.execute("SELECT value FROM meta WHERE key = 'last_seq'").fetchone()
        pending = db.execute("SELECT COUNT(*) FROM messages").fetchone()[0]
    return (int(last[0]) + 1 if last else 0), int(pending)


def edge(recording: Path, model: Path, cloud: str, state: Path, *extra: str,
         key: str | None = API_KEY, verbose: str = "") -> subprocess.CompletedProcess[str]:  # fmt: skip
    """``darkread edge run`` as a user types it; ``state`` is the user's XDG state directory."""
    env = {**os.environ, "XDG_STATE_HOME": str(state)}
    env.pop("DARKREAD_EDGE_UPLINK_API_KEY", None)
    if key is not None:
        env["DARKREAD_EDGE_UPLINK_API_KEY"] = key
    command = [sys.executable, "-m", "darkread", *([verbose] if verbose else []), "edge", "run", "--replay", str(recording), "--speed", "max",
               "--model", str(model), "--cloud", cloud, "--drain-timeout", "3", *extra]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=180, cwd=state.parent)


def session_of(result: subprocess.CompletedProcess[str]) -> str:
    """The session the edge streamed (its ``ready:`` line names it)."""
    return re.search(r"\(session ([^,)]+)", result.stderr).group(1)  # type: ignore[union-attr]


def error_lines(result: subprocess.CompletedProcess[str]) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.startswith("darkread:")]


def the_line(result: subprocess.CompletedProcess[str]) -> str:
    """The run's one ``darkread: error:`` line, and it is the last line (no traceback anywhere)."""
    lines = error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("darkread: error: "), result.stderr[-3000:]
    assert result.stderr.strip().splitlines()[-1] == lines[0]
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    return lines[0]


def final_spool(result: subprocess.CompletedProcess[str]) -> tuple[int, int]:
    """(depth, lost) from the edge's last metrics line (``spool 13 (lost 0)``)."""
    line = next(line for line in reversed(result.stderr.splitlines()) if " final: " in line)
    depth, lost = re.search(r"spool (\d+) \(lost (\d+)\)", line).groups()  # type: ignore[union-attr]
    return int(depth), int(lost)


def row(case: str, command: str, result: subprocess.CompletedProcess[str], counts: str) -> None:
    print(f"| {case} | `{command}` | {result.returncode} | {the_line(result) if result.returncode else '-'} | {counts} |")


def test_the_edge_log_holds_no_key(tmp_path: Path, recording: Path, model: Path) -> None:
    """A key in the cloud URL (and a dead instance before it, so the fail-over is logged too)."""
    cloud = Cloud(tmp_path / "cloud", free_port())
    cloud.start()
    dead = f"ws://127.0.0.1:{free_port()}/v1/stream?key={API_KEY}"
    try:
        # -vv: the debug log too, where the websocket library writes the request and its X-API-Key header
        result = edge(recording, model, f"{dead},{cloud.ws_url}?key={API_KEY}", tmp_path / "state",
                      "--session", "keyed", verbose="-vv")
        stored = cloud.stored_seqs("keyed")
    finally:
        cloud.stop()
    assert result.returncode == 0, result.stderr[-3000:]
    log = result.stderr
    assert "uplink connected to" in log and "ready:" in log and "fails over" in log  # the URLs are logged ...
    assert log.count(API_KEY) == 0, [line for line in log.splitlines() if API_KEY in line]  # ... without the key
    assert "key=REDACTED" in log
    print(f"edge log: {len(log.splitlines())} lines, {log.count('key=REDACTED')} URLs with key=REDACTED, "
          f"{log.count(API_KEY)} occurrences of the key; {len(stored)} frames stored")


def test_unreachable_cloud_keeps_frames_in_the_default_spool_and_says_so(
    tmp_path: Path, recording: Path, model: Path
) -> None:
    port = free_port()
    state = tmp_path / "state"
    url = f"ws://127.0.0.1:{port}/v1/stream"
    first = edge(recording, model, url, state)
    spool = state / "darkread" / "spool"
    made, pending = spool_counts(spool)  # on disk by default, under the user's state directory
    line = the_line(first)
    assert first.returncode == 3
    assert url in line and str(spool) in line and staying(pending) in line, line
    assert made == pending > 0
    assert final_spool(first) == (pending, 0)
    assert [int(n) for n in SPOOLED.findall(first.stderr)] == [pending] * len(SPOOLED.findall(first.stderr))
    cloud = Cloud(tmp_path / "cloud", port)
    cloud.start()
    try:
        second = edge(recording, model, url, state)  # same spool: resumes its session
        session = session_of(second)
        stored = cloud.stored_seqs(session)
    finally:
        cloud.stop()
    assert second.returncode == 0, second.stderr[-3000:]
    made_total, left = spool_counts(spool)
    assert stored == list(range(made_total)) and left == 0  # the first run's frames once, then the second's
    row("unreachable cloud, default spool", f"edge run --cloud {url}", first,
        f"made {made}, sent 0, spooled {pending}; after a restart with the cloud up: stored {len(stored)} of "
        f"{made_total} made, still spooled {left}")


def test_unreachable_cloud_with_a_memory_spool_says_how_many_were_lost(
    tmp_path: Path, recording: Path, model: Path
) -> None:
    url = f"ws://127.0.0.1:{free_port()}/v1/stream"
    result = edge(recording, model, url, tmp_path / "state", "--spool", ":memory:")
    line = the_line(result)
    depth, lost = final_spool(result)
    assert result.returncode == 3
    assert lost > 0 and depth == 0 and f"{lost} messages are lost" in line and "in memory" in line, line
    assert not (tmp_path / "state").exists()  # asked for memory: nothing on disk
    row("unreachable cloud, memory spool", f"edge run --cloud {url} --spool :memory:", result,
        f"made {lost}, sent 0, lost {lost} (log: spool {depth} (lost {lost}))")


def test_a_wrong_key_ends_the_run_with_counts_that_agree(tmp_path: Path, recording: Path, model: Path) -> None:
    cloud = Cloud(tmp_path / "cloud", free_port())
    cloud.start()
    state = tmp_path / "state"
    try:
        first = edge(recording, model, cloud.ws_url, state, key="wrong-key")
        spool = state / "darkread" / "spool"
        made, pending = spool_counts(spool)
        second = edge(recording, model, cloud.ws_url, state)
        session = session_of(second)
        stored = cloud.stored_seqs(session)
    finally:
        cloud.stop()
    line = the_line(first)
    assert first.returncode == 1 and "API key" in line and staying(pending) in line, line
    counts = [int(n) for n in SPOOLED.findall(first.stderr)]
    assert counts and set(counts) == {pending}, first.stderr[-3000:]  # no "0 messages stay" before "6 in the spool"
    assert second.returncode == 0, second.stderr[-3000:]
    made_total, left = spool_counts(spool)
    assert stored == list(range(made_total)) and left == 0
    row("wrong key", "edge run (DARKREAD_EDGE_UPLINK_API_KEY=wrong-key)", first,
        f"made {made}, sent 0, spooled {pending}; after a restart with the right key: stored {len(stored)} of "
        f"{made_total} made, still spooled {left}")


def test_a_read_only_spool_disk(tmp_path: Path, recording: Path, model: Path) -> None:
    with small_disk(tmp_path / "disk", 32768) as disk:  # room for two runs and their WAL: only read-only is tested here
        spool = disk.path / "spool"
        port = free_port()
        url = f"ws://127.0.0.1:{port}/v1/stream"
        first = edge(recording, model, url, tmp_path / "state", "--spool", str(spool))  # no cloud: frames stay
        made, pending = spool_counts(spool)
        assert first.returncode == 3 and pending == made > 0, first.stderr[-3000:]
        disk.read_only()
        result = edge(recording, model, url, tmp_path / "state", "--spool", str(spool))
        line = the_line(result)
        assert result.returncode == 4 and str(spool) in line and "read-only file system" in line, line
        disk.writable()
        assert spool_counts(spool) == (made, pending)  # untouched
        cloud = Cloud(tmp_path / "cloud", port)
        cloud.start()
        try:
            again = edge(recording, model, url, tmp_path / "state", "--spool", str(spool))
            session = session_of(again)
            stored = cloud.stored_seqs(session)
        finally:
            cloud.stop()
        assert again.returncode == 0, again.stderr[-3000:]
        made_total, left = spool_counts(spool)
        assert stored == list(range(made_total)) and left == 0
    row("read-only spool disk", "edge run --spool <read-only>/spool", result,
        f"{pending} spooled before, 0 sent; after remounting rw and a restart: stored {len(stored)} of {made_total} "
        f"made, still spooled {left}")


def test_a_full_spool_disk(tmp_path: Path, recording: Path, model: Path) -> None:
    cloud = Cloud(tmp_path / "cloud", free_port())
    cloud.start()
    try:
        with small_disk(tmp_path / "disk", 8192) as disk:  # the WAL of a run takes a few MB before its checkpoint
            spool = disk.path / "spool"
            disk.fill(leave_kb=160)  # room for the spool to open and take its first messages, then full
            result = edge(recording, model, cloud.ws_url, tmp_path / "state", "--spool", str(spool))
            made, pending = spool_counts(spool)
            session = session_of(result)
            stored_first = len(cloud.stored_seqs(session))
            disk.empty_filler()
            again = edge(recording, model, cloud.ws_url, tmp_path / "state", "--spool", str(spool))
            # the restart resumes the session while the spool still holds some of it; had the cloud
            # taken all of it before the disk filled (a slow host), the restart is a session of its own
            first_session = cloud.stored_seqs(session)
            stored = cloud.stored_seqs(session_of(again))
            made_total, left = spool_counts(spool)
    finally:
        cloud.stop()
    line = the_line(result)
    assert result.returncode == 4 and str(spool) in line and "disk is full" in line, line
    assert again.returncode == 0, again.stderr[-3000:]
    assert first_session == list(range(len(first_session)))  # the first run's session whole, nothing twice
    assert stored == list(range(made_total)) and left == 0  # nothing lost behind the full disk
    row("full spool disk", "edge run --spool <full>/spool", result,
        f"made {made} before the disk was full, stored {stored_first}, spooled {pending}; after freeing the disk and "
        f"a restart: stored {len(stored)} of {made_total} made, still spooled {left}")
