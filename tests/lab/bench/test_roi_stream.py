"""The bench's two-pass ROI measurement (lab/bench/roi_stream.py) on a short simulated recording with
its gyroscope stream: the second pass replays only what the first delivered and makes the same frames."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from darkread.edge.io.raw import read_raw
from darkread.edge.sources.replay import ReplaySource
from darkread.lab.bench.edge import FULL_VIEW, IMU_ROI, SMOKE_VIEW_SPEC, _mode_run
from darkread.lab.bench.roi_stream import Deliveries, record_deliveries, replay_as_delivered, write_delivered
from darkread.models.synth.recording import write_recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("roi_stream") / "reading"
    write_recording(out, dataclasses.replace(SMOKE_VIEW_SPEC, seconds=1.0), progress=False)
    return out


def test_the_second_pass_replays_what_the_first_delivered_and_makes_the_same_frames(recording: Path, tmp_path: Path) -> None:
    kept: list[Deliveries] = []

    def keep(source: ReplaySource) -> Deliveries:
        kept.append(record_deliveries(source))
        return kept[-1]

    whole = _mode_run(recording, None, "on-change", FULL_VIEW)
    first = _mode_run(recording, None, "on-change", IMU_ROI, keep)
    deliveries = kept[0]
    assert deliveries.roi_writes, "the gyroscope is healthy after its first 100 ms: the edge narrows the sensor"
    assert all(roi[2] < 1280 for _, roi in deliveries.roi_writes[:1])
    delivered = write_delivered(recording, deliveries, tmp_path / "delivered")

    written = read_raw(delivered / "events.raw").events
    assert np.array_equal(written, deliveries.events)  # the EVT3 file holds exactly what crossed "USB"
    assert first["events_out"] == written.shape[0] < whole["events_out"]
    assert first["words_outside_roi"] > 0

    second_log: list[Deliveries] = []

    def log(source: ReplaySource) -> Deliveries:
        second_log.append(replay_as_delivered(source, deliveries))
        return second_log[-1]

    second = _mode_run(delivered, None, "on-change", IMU_ROI, log)
    assert second["frames"] > 0
    assert (second["frames"], second["views"], second["messages_sha256"]) == (first["frames"], first["views"], first["messages_sha256"])
    assert second["events_out"] == first["events_out"] and second["words_outside_roi"] == 0
    # the writes that took effect are the same; after the last one only when the replay's chunks
    # end decides (the gyroscope's file ends before the events: the whole sensor comes back at a chunk)
    in_effect = [roi for k, (_, roi) in enumerate(deliveries.roi_writes) if k in deliveries.effective]
    assert in_effect and [roi for _, roi in second_log[0].roi_writes][: len(in_effect)] == in_effect


def test_the_second_pass_says_which_roi_the_edge_programmed(recording: Path) -> None:
    # the light estimate counts the background only while the sensor is whole: asked in the second
    # pass, the replay must answer as the first did (it answered "whole" throughout, and the 30-lux
    # full view measured 200 lux there against 11.6 in the first pass)
    source = ReplaySource(recording / "events.raw", speed=None)
    replay_as_delivered(source, Deliveries())
    assert source.roi == (0, 0, source.width, source.height)
    source.set_roi(100, 50, 300, 200)
    assert source.roi == (100, 50, 300, 200)
    source.set_roi(0, 0, source.width, source.height)
    assert source.roi == (0, 0, source.width, source.height)
