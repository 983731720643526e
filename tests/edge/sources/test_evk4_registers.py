from __future__ import annotations

import pytest

from darkread.edge.sources.evk4 import registers as regs


def test_init_has_the_documented_shape() -> None:
    writes = [op for op in regs.INIT if isinstance(op, regs.Write)]
    delays = [op for op in regs.INIT if isinstance(op, regs.Delay)]
    assert (len(writes), len(delays)) == (67, 14)
    assert writes[0] == regs.Write(0x001C, 1)
    assert writes[-1] == regs.Write(0x9000, 0x200)
    assert regs.sequence_delay_us(regs.INIT) == 2_503_610  # ~2.5 s on hardware, injectable in tests


def test_start_and_stop_touch_pixel_reset_and_time_base() -> None:
    assert regs.START[-1] == regs.Field(0x0004, 0x400, 0x400)
    assert regs.STOP[0] == regs.Field(0x0004, 0x400, 0)
    assert regs.Field(0x9008, 1, 1) in regs.START and regs.Field(0x9008, 1, 0) in regs.STOP


@pytest.mark.parametrize(("rate", "count"), [(20e6, 4000), (0, 0), (1e6, 200), (3.2e9, 640_000)])
def test_erc_event_count(rate: float, count: int) -> None:
    assert regs.erc_event_count(rate) == count


@pytest.mark.parametrize("rate", [-1.0, 3.3e9])
def test_erc_rate_out_of_range(rate: float) -> None:
    with pytest.raises(ValueError, match=r"outside \[0, 3.2e\+09\] ev/s"):
        regs.erc_event_count(rate)


def test_erc_init_loads_both_luts_between_mode_changes() -> None:
    seq = regs.erc_init_sequence()
    assert seq[0] == regs.Field(0x6000, 0b11, 0) and seq[-1] == regs.Field(0x6000, 0b11, 1)
    lut = [op for op in seq if isinstance(op, regs.Write)]
    assert len(lut) == 230 + 256
    assert regs.Write(0x6404, 2 | (3 << 16)) in lut


def test_roi_window_words_pack_x_and_y() -> None:
    assert regs.roi_window_words(100, 200, 300, 100) == (100 | (200 << 16), 400 | (300 << 16))


@pytest.mark.parametrize("window", [(-1, 0, 10, 10), (0, 0, 1281, 10), (1200, 0, 100, 10), (0, 700, 10, 30), (0, 0, 0, 5)])
def test_roi_outside_sensor_rejected(window: tuple[int, int, int, int]) -> None:
    with pytest.raises(ValueError):
        regs.roi_window_words(*window)


def test_line_reset_covers_40_columns_and_23_rows() -> None:
    addrs = [op.addr for op in regs.ROI_LINES_RESET]
    assert addrs[0] == 0x2000 and 0x209C in addrs and addrs[-1] == 0x4058 and len(addrs) == 63


def test_bias_encoding() -> None:
    assert regs.bias_write_value(0x66) == 0x11A10066
    assert {name: spec.addr for name, spec in regs.BIASES.items()} == {
        "fo": 0x1004, "hpf": 0x100C, "diff_on": 0x1010, "diff_off": 0x1018, "refr": 0x1020,
    }  # fmt: skip
