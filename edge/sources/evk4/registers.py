"""IMX636 (EVK4 / EVK3 HD) register map and bring-up sequences, kept as data.

Every sequence is a tuple of operations applied in order by ``apply_sequence``:

- ``Write(addr, value)``: write a 32-bit register;
- ``Field(addr, mask, value)``: read-modify-write, only the bits in ``mask`` change;
- ``Delay(us)``: wait (scaled by the caller, so tests run without real delays).

Sources the values were learned from (OpenEB 5.1.1, ``hal_psee_plugins/``):

- init / start / stop / destroy: ``include/devices/imx636/imx636_evk3_issd.h`` and the order
  stop → destroy → init used on open by ``src/devices/treuzell/tz_issd_device.cpp``;
- detection: ``src/devices/imx636/imx636_tz_device.cpp`` (``can_build``);
- register names and reset values: ``include/devices/imx636/register_maps/imx636_registermap.h``;
- biases: ``src/devices/imx636/imx636_ll_biases.cpp``,
  ``include/devices/imx636/imx636_bias_settings.h``, ``imx636_bias_settings_iterator.h``;
- event rate controller: ``src/devices/gen41/gen41_erc.cpp``;
- region of interest: ``src/devices/gen41/gen41_roi_command.cpp``;
- output format: ``TzImx636::set_output_format`` in ``src/devices/imx636/imx636_tz_device.cpp``.
Factory bias values used by the fake device: neuromorphic-drivers
``python/python/neuromorphic_drivers/generated/devices/prophesee_evk4.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

# --- USB identity -----------------------------------------------------------------------------

CYPRESS_VID = 0x04B4
EVK4_PID = 0x00F5
EVK3_PID = 0x00F4
BOOTLOADER_PID = 0x00F3

# (vendor, product, name): boards that speak Treuzell with an IMX636 behind it.
SUPPORTED_USB_IDS: tuple[tuple[int, int, str], ...] = (
    (CYPRESS_VID, EVK4_PID, "Prophesee EVK4"),
    (CYPRESS_VID, EVK3_PID, "Prophesee EVK3 HD"),
    (0x31F7, 0x0003, "Century Arks SilkyEvCam HD"),
    (0x1409, 0x8E00, "IDS XCP-E"),
)

TREUZELL_INTERFACE = 0
TREUZELL_CLASS = 0xFF
TREUZELL_SUBCLASS = 0x19
EP_CONTROL_OUT = 0x02
EP_CONTROL_IN = 0x82
EP_DATA_IN = 0x81

CONTROL_WRITE_TIMEOUT_MS = 1000
CONTROL_READ_TIMEOUT_MS = 10000
DATA_READ_TIMEOUT_MS = 100

# Cypress boards older than this firmware are refused by OpenEB; below bcdDevice 0x0307 the
# alternate setting must not be selected.
MIN_FIRMWARE_VERSION = 0x030800
MIN_BCD_DEVICE_FOR_ALTSETTING = 0x0307

SENSOR_DEVICE_ID = 0  # Treuzell device index of the sensor on EVK3/EVK4
WIDTH = 1280
HEIGHT = 720

# --- sequence operations ----------------------------------------------------------------------


class Write(NamedTuple):
    addr: int
    value: int


class Field(NamedTuple):
    addr: int
    mask: int
    value: int


class Delay(NamedTuple):
    us: int


Operation = Write | Field | Delay
RegisterSequence = tuple[Operation, ...]

# --- detection --------------------------------------------------------------------------------

REG_SENSOR_ID = 0x0014
IMX636_SENSOR_ID = 0xA0401806
REG_SENSOR_VARIANT = 0xF128  # low two bits are 0 on IMX636 (non-zero on look-alike Gen4.1 parts)

# --- global registers -------------------------------------------------------------------------

REG_ROI_CTRL = 0x0004
ROI_TD_EN = 1 << 1
ROI_TD_SHADOW_TRIGGER = 1 << 5
ROI_TD_RONI_N_EN = 1 << 6  # 1: keep the inside of the window (ROI), 0: drop it (RONI)
PX_TD_RSTN = 1 << 10  # pixel reset released: the analog front end runs

REG_ROI_WIN_CTRL = 0x0034
ROI_MASTER_EN = 1 << 0
ROI_WIN_DONE = 1 << 1
REG_ROI_WIN_START = 0x0038
REG_ROI_WIN_END = 0x003C
ROI_X_MASK = 0x7FF  # bits [10:0]
ROI_Y_SHIFT = 16  # y in bits [25:16]
ROI_Y_MASK = 0x3FF

ROI_COLUMN_REGS = tuple(range(0x2000, 0x20A0, 4))  # 40 × 32 columns, bit set = column disabled
ROI_ROW_REGS = tuple(range(0x4000, 0x405C, 4))  # 23 × 32 rows (the last holds 16 rows)

REG_EDF_PIPELINE_CONTROL = 0x7000
EDF_FORMAT_EVT21 = 1 << 1  # 0 = EVT3
REG_EOI_8000 = 0x8000
EOI_FORMAT_MASK = 0b11 << 6
EOI_FORMAT_EVT3 = 0b10 << 6

REG_TIME_BASE_CTRL = 0x9008

# --- sequences --------------------------------------------------------------------------------

# Power-up, PLL and readout configuration; leaves the sensor configured for EVT3 but not started.
# Learned from: hal_psee_plugins/include/devices/imx636/imx636_evk3_issd.h (init).
INIT: RegisterSequence = (
    Write(0x001C, 0x00000001),
    Delay(1_000_000),
    Write(0x00400004, 0x00000001),
    Delay(500_000),
    Write(0x00400004, 0x00000000),
    Delay(1_000_000),
    Write(0xB000, 0x00000158),
    Delay(300),
    Write(0xB044, 0x00000000),
    Write(0xB004, 0x0000000A),
    Write(0xB040, 0x00000000),
    Write(0xB0C8, 0x00000000),
    Write(0xB040, 0x00000000),
    Write(0xB040, 0x00000000),
    Write(0x0000, 0x4F006442),
    Write(0x0000, 0x0F006442),
    Write(0x00B8, 0x00000400),
    Write(0x00B8, 0x00000400),
    Write(0xB07C, 0x00000000),
    Write(0xB074, 0x00000002),
    Write(0xB078, 0x000000A0),
    Write(0x00C0, 0x00000110),
    Write(0x00C0, 0x00000210),
    Write(0xB120, 0x00000001),
    Write(0xE120, 0x00000000),
    Write(0xB068, 0x00000004),
    Write(0xB07C, 0x00000001),
    Delay(10),
    Write(0xB07C, 0x00000003),
    Delay(1000),
    Write(0x00B8, 0x00000401),
    Write(0x00B8, 0x00000409),
    Write(0x0000, 0x4F006442),
    Write(0x0000, 0x4F00644A),
    Write(0xB080, 0x00000077),
    Write(0xB084, 0x0000000F),
    Write(0xB088, 0x00000037),
    Write(0xB08C, 0x00000037),
    Write(0xB090, 0x000000DF),
    Write(0xB094, 0x00000057),
    Write(0xB098, 0x00000037),
    Write(0xB09C, 0x00000067),
    Write(0xB0A0, 0x00000037),
    Write(0xB0A4, 0x0000002F),
    Write(0xB0AC, 0x00000028),
    Write(0xB0CC, 0x00000001),
    Write(0xB000, 0x000002F8),
    Write(0xB004, 0x0000008A),
    Write(0xB01C, 0x00000030),
    Write(0xB020, 0x00002000),
    Write(0xB02C, 0x000000FF),
    Write(0xB030, 0x00003E80),
    Write(0xB028, 0x00000FA0),
    Write(0xA000, 0x000B0501),
    Delay(200),
    Write(0xA008, 0x00002405),
    Delay(200),
    Write(0xA004, 0x000B0501),
    Delay(200),
    Write(0xA020, 0x00000150),
    Delay(200),
    Write(0xB040, 0x00000007),
    Write(0xB064, 0x00000006),
    Write(0xB040, 0x0000000F),
    Delay(100),
    Write(0xB004, 0x0000008A),
    Delay(200),
    Write(0xB0C8, 0x00000003),
    Delay(200),
    Write(0xB044, 0x00000001),
    Write(0xB000, 0x000002F9),
    Write(0x7008, 0x00000001),
    Write(0x7000, 0x00070001),
    Write(0x8000, 0x0001E085),
    Write(0x9008, 0x00000644),
    Write(0x0004, 0xF0005042),
    Write(0x0018, 0x00000200),
    Write(0x1014, 0x11A1504D),
    Write(0x9004, 0x00000000),
    Delay(1000),
    Write(0x9000, 0x00000200),
)

# Digital then analog start: time base on, pixel reset released. Learned from: hal_psee_plugins/include/devices/imx636/imx636_evk3_issd.h (start).
START: RegisterSequence = (
    Write(0xB000, 0x000002F9),
    Write(0x9028, 0x00000000),
    Field(REG_TIME_BASE_CTRL, 0x00000001, 0x00000001),
    Write(0x002C, 0x0022C724),
    Field(REG_ROI_CTRL, PX_TD_RSTN, PX_TD_RSTN),
)

# Analog then digital stop; the 1 ms lets the readout flush before the time base halts.
# Learned from: hal_psee_plugins/include/devices/imx636/imx636_evk3_issd.h (stop).
STOP: RegisterSequence = (
    Field(REG_ROI_CTRL, PX_TD_RSTN, 0),
    Write(0x002C, 0x0022C324),
    Write(0x9028, 0x00000002),
    Delay(1000),
    Field(REG_TIME_BASE_CTRL, 0x00000001, 0),
    Write(0xB000, 0x000002F8),
    Delay(300),
)

# Power-down: PLL and bias generator off, digital blocks back to reset.
# Learned from: hal_psee_plugins/include/devices/imx636/imx636_evk3_issd.h (destroy).
DESTROY: RegisterSequence = (
    Write(0x0070, 0x00400008),
    Write(0x006C, 0x0EE47114),
    Delay(500),
    Write(0xA00C, 0x00020400),
    Delay(500),
    Write(0xA010, 0x00008068),
    Delay(200),
    Write(0x1104, 0x00000000),
    Delay(200),
    Write(0xA020, 0x00000050),
    Delay(200),
    Write(0xA004, 0x000B0500),
    Delay(200),
    Write(0xA008, 0x00002404),
    Delay(200),
    Write(0xA000, 0x000B0500),
    Write(0xB044, 0x00000000),
    Write(0xB004, 0x0000000A),
    Write(0xB040, 0x0000000E),
    Write(0xB0C8, 0x00000000),
    Write(0xB040, 0x00000006),
    Write(0xB040, 0x00000004),
    Write(0x0000, 0x4F006442),
    Write(0x0000, 0x0F006442),
    Write(0x00B8, 0x00000401),
    Write(0x00B8, 0x00000400),
    Write(0xB07C, 0x00000000),
)

# EVT3 output (INIT already selects it; written again so a board left in EVT2.1 recovers).
# Learned from: hal_psee_plugins/src/devices/imx636/imx636_tz_device.cpp (set_output_format).
FORMAT_EVT3: RegisterSequence = (
    Field(REG_EDF_PIPELINE_CONTROL, EDF_FORMAT_EVT21, 0),
    Field(REG_EOI_8000, EOI_FORMAT_MASK, EOI_FORMAT_EVT3),
)

# Every column and row enabled (line masks are inverted: 0 = enabled); the last row register
# holds 16 rows in its low half. Learned from: hal_psee_plugins/src/devices/gen41/gen41_roi_command.cpp
# (reset_to_full_roi) and the register map's td_roi_x00..x39 / td_roi_y00..y22.
ROI_LINES_RESET: RegisterSequence = (
    *(Write(addr, 0) for addr in ROI_COLUMN_REGS),
    *(Write(addr, 0) for addr in ROI_ROW_REGS[:-1]),
    Field(ROI_ROW_REGS[-1], 0xFFFF, 0),
)

# --- biases -----------------------------------------------------------------------------------

BIAS_CONF = 0x11A10000  # upper bits every bias write carries
BIAS_VALUE_MASK = 0xFF


@dataclass(frozen=True)
class BiasSpec:
    """One settable bias: its register and the offset ranges OpenEB allows / recommends."""

    addr: int
    allowed: tuple[int, int]
    recommended: tuple[int, int]
    effect: str


BIASES: dict[str, BiasSpec] = {
    "fo": BiasSpec(0x1004, (-150, 200), (-35, 55), "low-pass filter bandwidth"),
    "hpf": BiasSpec(0x100C, (0, 255), (0, 120), "high-pass filter"),
    "diff_on": BiasSpec(0x1010, (-150, 200), (-85, 140), "ON contrast threshold (lower = more events)"),
    "diff_off": BiasSpec(0x1018, (-150, 200), (-35, 190), "OFF contrast threshold (lower = more events)"),
    "refr": BiasSpec(0x1020, (-50, 255), (-20, 235), "refractory period, caps the per-pixel rate"),
}
REG_BIAS_DIFF = 0x1014  # reference for diff_on/diff_off; not meant to be changed

# Factory values of an EVK4 (the fake device starts with these).
FACTORY_BIAS_VALUES: dict[str, int] = {"fo": 0x53, "hpf": 0x00, "diff_on": 0x66, "diff_off": 0x49, "refr": 0x14}


def bias_write_value(value: int) -> int:
    """Register word for an absolute 8-bit bias value."""
    return (value & BIAS_VALUE_MASK) | BIAS_CONF


# --- event rate controller (ERC) --------------------------------------------------------------

REG_ERC_MODE = 0x6000  # bits [1:0]: 1 = ERC block active
REG_ERC_IN_DROP_RATE_CONTROL = 0x6004
REG_ERC_REFERENCE_PERIOD = 0x6008
REG_ERC_TARGET_EVENT_COUNT = 0x600C
REG_ERC_ENABLE = 0x6028
REG_ERC_LUT_LOAD = 0x602C
REG_ERC_T_DROPPING = 0x6050
REG_ERC_H_DROPPING = 0x6060
REG_ERC_V_DROPPING = 0x6070
ERC_REFERENCE_PERIOD_US = 200
ERC_MAX_EVENT_COUNT = 640_000  # per reference period
ERC_DEFAULT_EVENT_COUNT = 4000  # 20 Mev/s with a 200 µs period
ERC_DELAY_LUT_REGS = tuple(range(0x6800, 0x6800 + 4 * 230, 4))
ERC_T_DROP_LUT_REGS = tuple(range(0x6400, 0x6400 + 4 * 256, 4))


def erc_event_count(rate_ev_s: float, period_us: int = ERC_REFERENCE_PERIOD_US) -> int:
    """Events allowed per reference period for a target rate; ValueError outside the hardware range."""
    max_rate = ERC_MAX_EVENT_COUNT * 1e6 / period_us
    if not 0 <= rate_ev_s <= max_rate:
        raise ValueError(f"ERC rate {rate_ev_s:g} ev/s is outside [0, {max_rate:g}] ev/s")
    return round(rate_ev_s * period_us / 1e6)


def erc_init_sequence(event_count: int = ERC_DEFAULT_EVENT_COUNT) -> RegisterSequence:
    """ERC block configured with the linear drop LUT, dropping still disabled.

    Learned from: hal_psee_plugins/src/devices/gen41/gen41_erc.cpp (initialize, enable).
    """
    return (
        Field(REG_ERC_MODE, 0b11, 0),
        Field(REG_ERC_IN_DROP_RATE_CONTROL, 0b1, 1),
        Field(REG_ERC_REFERENCE_PERIOD, 0x3FF, ERC_REFERENCE_PERIOD_US),
        Field(REG_ERC_TARGET_EVENT_COUNT, 0x3FFFFF, event_count),
        Field(REG_ERC_ENABLE, 0b111, 0b011),
        Field(REG_ERC_LUT_LOAD, 0b1, 1),
        *(Write(addr, 0x08080808) for addr in ERC_DELAY_LUT_REGS),
        Field(REG_ERC_LUT_LOAD, 0b1, 0),
        *(Write(addr, (2 * i) | ((2 * i + 1) << 16)) for i, addr in enumerate(ERC_T_DROP_LUT_REGS)),
        Field(REG_ERC_T_DROPPING, 0b1, 0),
        Field(REG_ERC_H_DROPPING, 0b1, 0),
        Field(REG_ERC_V_DROPPING, 0b1, 0),
        Field(REG_ERC_MODE, 0b11, 1),
    )


def erc_sequence(rate_ev_s: float | None) -> RegisterSequence:
    """Enable temporal dropping at ``rate_ev_s`` (``None`` disables it)."""
    if rate_ev_s is None:
        return (Field(REG_ERC_T_DROPPING, 0b1, 0),)
    count = erc_event_count(rate_ev_s)
    return (Write(REG_ERC_TARGET_EVENT_COUNT, count), Field(REG_ERC_T_DROPPING, 0b1, 1))


# --- single-window analog ROI -----------------------------------------------------------------


def roi_window_words(x0: int, y0: int, width: int, height: int) -> tuple[int, int]:
    """Start and end register words of a window; ValueError when it leaves the sensor.

    The end is written as start + size, as OpenEB does; the reset value of the end register
    (1279, 719) suggests the hardware may treat it as inclusive, i.e. one extra column and row.
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"ROI size must be positive, got {width}x{height}")
    if x0 < 0 or y0 < 0 or x0 + width > WIDTH or y0 + height > HEIGHT:
        raise ValueError(
            f"ROI x0={x0} y0={y0} {width}x{height} leaves the {WIDTH}x{HEIGHT} sensor "
            f"(need 0 <= x0, x0+width <= {WIDTH}, 0 <= y0, y0+height <= {HEIGHT})"
        )
    start = x0 | (y0 << ROI_Y_SHIFT)
    end = (x0 + width) | ((y0 + height) << ROI_Y_SHIFT)
    return start, end


# Pixel reset (PX_TD_RSTN) is left alone so a ROI change never starts or stops the stream.
ROI_ENABLE_BITS = ROI_TD_EN | ROI_TD_SHADOW_TRIGGER | ROI_TD_RONI_N_EN


def roi_window_sequence(x0: int, y0: int, width: int, height: int) -> RegisterSequence:
    """Program the window and arm it (the caller then polls ``ROI_WIN_DONE``).

    Learned from: hal_psee_plugins/src/devices/gen41/gen41_roi_command.cpp (write_ROI_windows, enable).
    """
    start, end = roi_window_words(x0, y0, width, height)
    return (
        Write(REG_ROI_WIN_START, start),
        Write(REG_ROI_WIN_END, end),
        Field(REG_ROI_WIN_CTRL, ROI_MASTER_EN, ROI_MASTER_EN),
    )


# Applied after the window is latched: ROI mode, filtering on, shadow registers transferred.
ROI_ENABLE: RegisterSequence = (Field(REG_ROI_CTRL, ROI_ENABLE_BITS, ROI_ENABLE_BITS),)

# Full frame again: window disarmed; ROI filtering stays on as INIT leaves it (0xF0005042 has
# roi_td_en set) with every line enabled by ROI_LINES_RESET, so nothing is masked.
ROI_DISABLE: RegisterSequence = (
    Field(REG_ROI_WIN_CTRL, ROI_MASTER_EN | ROI_WIN_DONE, 0),
    Field(REG_ROI_CTRL, ROI_TD_EN | ROI_TD_SHADOW_TRIGGER, ROI_TD_EN | ROI_TD_SHADOW_TRIGGER),
)

# Register reset values the fake device starts from (only those the sequences read back).
RESET_VALUES: dict[int, int] = {
    REG_SENSOR_ID: IMX636_SENSOR_ID,
    REG_SENSOR_VARIANT: 0,
    REG_ROI_CTRL: 0xF0005042,
    REG_ROI_WIN_END: (WIDTH - 1) | ((HEIGHT - 1) << ROI_Y_SHIFT),
    REG_EDF_PIPELINE_CONTROL: 0xFFFF0001,
    REG_EOI_8000: 0x80,
    REG_TIME_BASE_CTRL: 0x640,
    ROI_ROW_REGS[-1]: 0x00FF0000,
    REG_ERC_REFERENCE_PERIOD: 0x80,
    REG_ERC_TARGET_EVENT_COUNT: 0x80,
    REG_BIAS_DIFF: bias_write_value(0x4D),
    **{spec.addr: bias_write_value(FACTORY_BIAS_VALUES[name]) for name, spec in BIASES.items()},
}


def sequence_delay_us(sequence: RegisterSequence) -> int:
    return sum(op.us for op in sequence if isinstance(op, Delay))
