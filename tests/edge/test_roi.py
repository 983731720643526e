"""When the sensor's ROI is on, and where it goes (edge.roi)."""

from __future__ import annotations

import pytest

from darkread.edge.config import PipelineConfig, load_config
from darkread.edge.roi import NOT_YET, delivered_since, follow_window, motion_healthy, parse_roi_mode, roi_wanted


class Known:
    """A known head motion without a word about its health (the simulator's pose)."""


class Gapped:
    """One that has a gap from 100 to 200 µs (an IMU stream that stalled)."""

    def healthy(self, t_us: int) -> bool:
        return not 100 <= t_us < 200


def test_follow_window_pads_clips_and_keeps_a_window_that_still_covers() -> None:
    assert follow_window((500, 300, 200, 100), None, 32) == (468, 268, 264, 164)
    assert follow_window((520, 290, 200, 100), (468, 268, 264, 164), 32) is None  # inside: no rewrite
    assert follow_window((540, 290, 200, 100), (468, 268, 264, 164), 32) == (508, 258, 264, 164)
    assert follow_window((1100, 650, 180, 70), None, 32, (1280, 720)) == (1068, 618, 212, 102)


def test_the_roi_is_wanted_while_a_known_motion_is_healthy() -> None:
    assert not motion_healthy(None, 0)
    assert motion_healthy(Known(), 150)  # no ``healthy``: present means healthy
    assert motion_healthy(Gapped(), 50) and not motion_healthy(Gapped(), 150)
    assert [roi_wanted("auto", Gapped(), t) for t in (50, 150, 250)] == [True, False, True]
    assert not roi_wanted("auto", None, 0)
    assert roi_wanted("on", None, 0) and not roi_wanted("off", Known(), 0)
    assert not roi_wanted("auto", Known(), 0, light_probe=True)  # the light is read on the whole sensor ...
    assert roi_wanted("on", Known(), 0, light_probe=True)  # ... unless the ROI is forced on


def test_the_mode_reads_booleans_as_on_and_off() -> None:
    assert PipelineConfig().sensor_roi == "auto"
    assert [parse_roi_mode(v) for v in (True, False, "AUTO", "yes", "0")] == ["on", "off", "auto", "on", "off"]
    assert PipelineConfig(sensor_roi=True).sensor_roi == "on"  # type: ignore[arg-type]
    config = load_config(None, environ={"DARKREAD_EDGE_PIPELINE_SENSOR_ROI": "false"})
    assert config.pipeline.sensor_roi == "off"
    with pytest.raises(ValueError, match="sensor_roi: cannot use 'sometimes'"):
        load_config(None, environ={}, overrides={"pipeline": {"sensor_roi": "sometimes"}})


def test_a_window_is_delivered_since_the_oldest_of_the_latest_rois_that_all_cover_it() -> None:
    window = (100, 100, 200, 100)
    covering, elsewhere = (80, 80, 264, 164), (500, 300, 264, 164)
    assert delivered_since([], window) is None  # the whole sensor, always
    assert delivered_since([(1_000, covering)], window) is None  # the whole sensor before, this since
    assert delivered_since([(1_000, elsewhere), (2_000, covering)], window) == 2_000  # dark before 2 ms
    assert delivered_since([(1_000, elsewhere), (2_000, covering), (3_000, (90, 90, 264, 164))], window) == 2_000
    assert delivered_since([(1_000, elsewhere), (2_000, None), (3_000, covering)], window) == 2_000  # whole sensor counts
    assert delivered_since([(1_000, elsewhere), (None, elsewhere)], window) == NOT_YET  # moving away: not yet known
    # a pending write that covers the window changes nothing for it: the earlier writes answer
    assert delivered_since([(1_000, elsewhere), (None, covering)], window) == NOT_YET  # dark until it takes effect
    assert delivered_since([(None, covering)], window) is None  # the whole sensor before, and after the switch
    assert delivered_since([(1_000, covering), (None, (90, 90, 264, 164))], window) is None
    assert delivered_since([(1_000, elsewhere), (2_000, covering), (None, covering)], window) == 2_000
    assert delivered_since([(1_000, elsewhere), (None, elsewhere), (3_000, covering)], window) == 3_000  # never in effect
