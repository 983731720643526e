"""EVT 3.0 word types (bits 15..12 of each 16-bit word)."""

from __future__ import annotations

ADDR_Y = 0x0  # [10:0] row
ADDR_X = 0x2  # [11] polarity, [10:0] column: one event
VECT_BASE_X = 0x3  # [11] polarity, [10:0] base column of the following vectors
VECT_12 = 0x4  # 12-bit mask from the base, then base += 12
VECT_8 = 0x5  # 8-bit mask from the base, then base += 8
TIME_LOW = 0x6  # time bits 11..0
CONTINUED_4 = 0x7
TIME_HIGH = 0x8  # time bits 23..12
EXT_TRIGGER = 0xA  # [11:8] channel, [0] edge
OTHERS = 0xE
CONTINUED_12 = 0xF

LOOP_DROP = 2048  # a TIME_HIGH this far below the previous one is a wrap of the 24-bit base
TIME_LOOP_US = 1 << 24
