"""The firmware's constants (``firmware/final_control/wc_config.h``), as binary32
where the firmware uses float. ``tests/test_constants_sync.py`` fails when the two
files disagree."""

from __future__ import annotations

from wcdrive.firmware.f32 import f32

BAUD = 115200
CMD_MAX_LEN = 63
ERR_LINES_PER_TICK = 2

CONTROL_PERIOD_MS = 50
WATCHDOG_MS = 500
PIVOT_TICKS = 6

CPR = f32(10000.0)
WHEELBASE = f32(0.57)
WHEEL_RADIUS = f32(0.1524)
TWO_PI = f32(6.28318548)

MAX_WHEEL_SPEED = f32(17.59)
MAX_LINEAR = f32(2.68)
MAX_ANGULAR = f32(9.4)

ALPHA = f32(0.8)
ONE_MINUS_ALPHA = f32(1.0 - ALPHA)   # folded by gcc: 1.0f - 0.8f is exact
MAX_ACCEL = f32(5.0)
EMERGENCY_DECEL = f32(15.0)
PID_OUT_MAX = f32(100.0)
PWM_SCALE = f32(2.55)
KP_R, KI_R, KD_R = f32(7.0), f32(8.0), f32(0.15)
KP_L, KI_L, KD_L = f32(7.2), f32(8.5), f32(0.15)
STILL_SPEED = f32(0.05)
STILL_TICKS = 3

PIVOT_SPEED = f32(2.0)
PIVOT_THRESHOLD = f32(0.1)
PIVOT_START_SPEED = f32(0.5)

PPM_CHANNELS = 8
PPM_NEUTRAL = 1500
PPM_SPAN = 500
PPM_DEADBAND = 10
PPM_VALID_MIN = 900
PPM_VALID_MAX = 2100
PPM_MAX_WHEEL = f32(5.0)
PPM_FWD_CHANNEL = 1
PPM_TURN_CHANNEL = 3

MODE_WHEEL = 0
MODE_CMDVEL = 1
MODE_PPM = 2
MODE_NAMES = {MODE_WHEEL: "WHEEL", MODE_CMDVEL: "CMDVEL", MODE_PPM: "PPM"}

HIGH = 1
LOW = 0
