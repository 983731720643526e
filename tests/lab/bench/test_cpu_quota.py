"""The edge on a wearable's CPU budget: ``darkread edge run`` replaying the sample at real time in
a CPU quota (a real cgroup; skipped where none is writable)."""

from __future__ import annotations

from pathlib import Path

import pytest

from darkread.core.paths import SAMPLE_RECORDING
from darkread.lab.bench.cpu_quota import QuotaUnavailable, quota_backend, run_under_quota
from darkread.lab.bench.edge import _first_seconds

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def quota_kind() -> str:
    try:
        return quota_backend()[0]
    except QuotaUnavailable as exc:
        pytest.skip(str(exc))


def test_a_quarter_core_keeps_up_with_no_frame_lost(quota_kind: str) -> None:
    run = run_under_quota(0.25, SAMPLE_RECORDING)
    assert run.exit_code == 0, run.log_tail
    assert run.views >= 10 and run.frames_lost == 0  # the sample's 13 views, every one acknowledged
    assert run.shed_level == 0 and run.views_capped == 0 and run.shed_changes == 0
    assert run.view_latency_p99_ms < 500 and run.rss_growth_mb < 64


def test_a_starving_quota_sheds_inferences_and_says_so_never_events(quota_kind: str, tmp_path: Path) -> None:
    short = _first_seconds(SAMPLE_RECORDING, tmp_path / "short", 1.5)  # (a 3 % quota stretches it ~15x)
    run = run_under_quota(0.03, short)
    assert run.exit_code == 0, run.log_tail  # it finishes: no stall
    assert run.shed_changes >= 1 and run.shed_level >= 1  # in its log and its final metrics line
    assert run.views >= 1 and run.frames_lost == 0  # what was promised to the spool all arrived
    assert run.rss_growth_mb < 64 and run.rss_max_mb < 1024
