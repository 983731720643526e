from __future__ import annotations

import threading
from pathlib import Path

import pytest

from darkread.edge.spool import Spool


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
