from __future__ import annotations

import threading
from pathlib import Path

import pytest
from small_disk import small_disk

from darkread.edge.errors import SpoolError
from darkread.edge.spool import MEMORY, Spool, default_spool_dir, spool_directory


def fill(spool: Spool, n: int, size: int = 10) -> list[int]:
    seqs = []
    for _ in range(n):
        seq = spool.allocate_seq()
        spool.append(seq, bytes([seq % 256]) * size)
        seqs.append(seq)
    return seqs


def test_append_ack_pending_in_order() -> None:
    spool = Spool(None)
    seqs = fill(spool, 5)
    assert seqs == [0, 1, 2, 3, 4]
    assert spool.depth == 5 and spool.bytes_pending == 50
    assert spool.ack(1) == 2
    assert [seq for seq, _ in spool.pending()] == [2, 3, 4]
    assert [seq for seq, _ in spool.pending(after_seq=2, limit=1)] == [3]
    assert spool.pending()[0][1] == bytes([2]) * 10
    spool.discard(3)
    assert [seq for seq, _ in spool.pending()] == [2, 4]
    spool.discard(3)  # absent: nothing happens
    assert spool.depth == 2 and spool.bytes_pending == 20
    spool.ack(4)
    assert spool.depth == 0 and spool.bytes_pending == 0


def test_survives_restart_with_seq_and_session(tmp_path: Path) -> None:
    spool = Spool(tmp_path)
    fill(spool, 4)
    spool.set_session_id("s-1")
    spool.ack(0)
    spool.close()

    reopened = Spool(tmp_path)
    assert [seq for seq, _ in reopened.pending()] == [1, 2, 3]
    assert reopened.session_id() == "s-1"
    assert reopened.allocate_seq() == 4


def test_seq_never_reused_after_everything_was_acked(tmp_path: Path) -> None:
    spool = Spool(tmp_path)
    fill(spool, 3)
    spool.ack(2)
    spool.close()
    reopened = Spool(tmp_path)
    assert reopened.depth == 0
    assert reopened.allocate_seq() == 3


def test_a_new_session_on_an_empty_spool_numbers_from_zero(tmp_path: Path) -> None:
    """Every seq the spool ever sent would otherwise reach the new session as a placeholder."""
    spool = Spool(tmp_path)
    spool.set_session_id("s-1")
    fill(spool, 3)
    spool.ack(2)
    spool.close()
    reopened = Spool(tmp_path)
    reopened.set_session_id("s-1")  # the same session resumed: its count goes on
    assert reopened.allocate_seq() == 3
    reopened.set_session_id("s-2")
    assert reopened.allocate_seq() == 0
    reopened.close()
    again = Spool(tmp_path)
    assert again.session_id() == "s-2" and again.allocate_seq() == 0  # (nothing was stored under seq 0 yet)


def test_a_new_session_with_messages_waiting_keeps_counting() -> None:
    spool = Spool(None)
    spool.set_session_id("s-1")
    fill(spool, 2)
    spool.set_session_id("s-2")  # (an explicit session while the old one's messages wait)
    assert spool.allocate_seq() == 2


def test_ack_beyond_local_counter_moves_counter_forward() -> None:
    spool = Spool(None)
    spool.ack(41)
    assert spool.allocate_seq() == 42


def test_bounded_by_messages_drops_oldest() -> None:
    spool = Spool(None, max_messages=10)
    fill(spool, 25)
    assert spool.depth <= 10
    assert spool.dropped == 25 - spool.depth
    remaining = [seq for seq, _ in spool.pending(limit=100)]
    assert remaining == list(range(25 - len(remaining), 25))  # newest kept, contiguous


def test_bounded_by_bytes() -> None:
    spool = Spool(None, max_bytes=1000)
    fill(spool, 50, size=100)
    assert spool.bytes_pending <= 1000
    assert spool.dropped + spool.depth == 50


def test_rejects_nonpositive_bounds() -> None:
    with pytest.raises(ValueError):
        Spool(None, max_bytes=0)


def test_concurrent_appends_keep_unique_seqs() -> None:
    spool = Spool(None)
    threads = [threading.Thread(target=fill, args=(spool, 50)) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    seqs = [seq for seq, _ in spool.pending(limit=1000)]
    assert seqs == list(range(200))


def test_the_default_spool_is_on_disk_in_the_users_state_directory(tmp_path: Path) -> None:
    assert default_spool_dir({"XDG_STATE_HOME": str(tmp_path)}) == tmp_path / "darkread" / "spool"
    assert default_spool_dir({"HOME": str(tmp_path)}) == tmp_path / ".local" / "state" / "darkread" / "spool"
    assert default_spool_dir({"XDG_STATE_HOME": "relative", "HOME": str(tmp_path)}) == (
        tmp_path / ".local" / "state" / "darkread" / "spool")  # the XDG spec ignores relative paths
    assert spool_directory("", {"XDG_STATE_HOME": str(tmp_path)}) == tmp_path / "darkread" / "spool"
    assert spool_directory(MEMORY, {}) is None
    assert spool_directory(str(tmp_path / "mine"), {}) == tmp_path / "mine"


def test_one_spool_directory_serves_one_edge_at_a_time(tmp_path: Path) -> None:
    first = Spool(tmp_path)
    with pytest.raises(SpoolError, match=f"{tmp_path}.*in use by another edge"):
        Spool(tmp_path)
    first.close()
    Spool(tmp_path).close()  # free again once the first closed


def test_an_in_memory_spool_counts_what_it_held_at_close_as_lost() -> None:
    spool = Spool(None)
    fill(spool, 3)
    spool.ack(0)
    spool.close()
    assert spool.dropped == 2 and spool.depth == 0


def test_a_read_only_spool_names_the_spool_and_the_cause(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk", 1024) as disk:
        directory = disk.path / "spool"
        spool = Spool(directory)
        fill(spool, 5)
        spool.close()
        disk.read_only()
        with pytest.raises(SpoolError) as failure:
            Spool(directory)
        disk.writable()
        assert str(directory) in str(failure.value) and "read-only file system" in str(failure.value)
        assert [seq for seq, _ in Spool(directory).pending()] == [0, 1, 2, 3, 4]  # nothing lost


def test_a_full_disk_fails_the_append_rolls_it_back_and_names_the_cause(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk", 512) as disk:
        spool = Spool(disk.path / "spool")
        fill(spool, 3)
        disk.fill()
        seq = spool.allocate_seq()
        with pytest.raises(SpoolError) as failure:
            spool.append(seq, b"x" * 64 * 1024)
        message = str(failure.value)
        assert str(disk.path / "spool" / "spool.sqlite3") in message and "disk is full" in message, message
        assert f"seq {seq}" in message
        assert not spool._db.in_transaction  # rolled back: the connection is not left inside BEGIN
        assert spool.depth == 3 and spool.bytes_pending == 30
        disk.empty_filler()
        spool.append(seq, b"y" * 10)  # the same connection works again once there is room
        spool.close()
        assert [s for s, _ in Spool(disk.path / "spool").pending()] == [0, 1, 2, seq]


def test_a_failed_ack_is_rolled_back_and_keeps_the_messages(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk", 2048) as disk:
        spool = Spool(disk.path / "spool")
        fill(spool, 40, size=2000)
        disk.fill()
        with pytest.raises(SpoolError) as failure:
            spool.ack(30)
        assert "disk is full" in str(failure.value) and "seq 30" in str(failure.value)
        assert not spool._db.in_transaction
        assert spool.depth == 40  # the count still matches the table
        disk.empty_filler()
        assert spool.ack(30) == 31 and spool.depth == 9
