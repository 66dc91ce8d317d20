"""The firmware's constants, from ``protocol/spec.toml`` (the file that generates
``firmware/final_control/wc_config.h``), as binary32 where the firmware uses float.
``tests/protocol/test_protocol.py`` checks that every constant of the spec is here."""

from __future__ import annotations

from wcdrive.avr.f32 import div, f32
from wcdrive.protocol.spec import build_id, integer, real, text

# Serial link
BAUD = integer("BAUD")
CMD_MAX_LEN = integer("CMD_MAX_LEN")
ERR_LINES_PER_TICK = integer("ERR_LINES_PER_TICK")
PROTOCOL_VERSION = integer("PROTOCOL_VERSION")
PROTOCOL_VERSION_PLAIN = integer("PROTOCOL_VERSION_PLAIN")
FIRMWARE_VERSION = text("FIRMWARE_VERSION")
#: ``WC_BUILD_ID``, which the Makefile computes from the sources (the same hash).
BUILD_ID = build_id()
SEQ_MAX = integer("SEQ_MAX")
NUMBER_MAX_DIGITS = integer("NUMBER_MAX_DIGITS")
NUMBER_MAX_EXP_DIGITS = integer("NUMBER_MAX_EXP_DIGITS")
TX_CREDIT_MAX = integer("TX_CREDIT_MAX")
TX_CREDIT_BOOT = integer("TX_CREDIT_BOOT")
TX_CREDIT_PER_MS = integer("TX_CREDIT_PER_MS")
TX_LINE_MAX = integer("TX_LINE_MAX")
LINE_COUNTER_WRAP = integer("LINE_COUNTER_WRAP")

# Timing
CONTROL_PERIOD_MS = integer("CONTROL_PERIOD_MS")
WATCHDOG_MS = integer("WATCHDOG_MS")
PIVOT_TICKS = integer("PIVOT_TICKS")
NEUTRAL_TICKS = integer("NEUTRAL_TICKS")
NEUTRAL_FAULT_TICKS = integer("NEUTRAL_FAULT_TICKS")
INHIBIT_DEBOUNCE_TICKS = integer("INHIBIT_DEBOUNCE_TICKS")
INHIBIT_1_SPEED = f32(real("INHIBIT_1_SPEED"))
INHIBIT_2_SPEED = f32(real("INHIBIT_2_SPEED"))
INHIBIT_1_LATCH = integer("INHIBIT_1_LATCH")
INHIBIT_2_LATCH = integer("INHIBIT_2_LATCH")
#: The brake's manual release (push mode), read as a third inhibit input (its bit).
INHIBIT_PUSH = 4
#: The inputs that inhibit driving (speed 0; push mode always) and those that latch (bit 0
#: input 1, bit 1 input 2).
INHIBIT_STOP_MASK = (1 if INHIBIT_1_SPEED == 0.0 else 0) | (2 if INHIBIT_2_SPEED == 0.0 else 0) | INHIBIT_PUSH
INHIBIT_LATCH_MASK = (1 if INHIBIT_1_LATCH else 0) | (2 if INHIBIT_2_LATCH else 0)

# Geometry and encoders (seed section 1.4.2)
CPR = f32(real("CPR"))
WHEELBASE = f32(real("WHEELBASE"))
WHEEL_RADIUS = f32(real("WHEEL_RADIUS"))
TWO_PI = f32(real("TWO_PI"))

# Limits
MAX_WHEEL_SPEED = f32(real("MAX_WHEEL_SPEED"))
MAX_LINEAR = f32(real("MAX_LINEAR"))
MAX_ANGULAR = f32(real("MAX_ANGULAR"))

# Controller
ALPHA = f32(real("ALPHA"))
MAX_ACCEL = f32(real("MAX_ACCEL"))
EMERGENCY_DECEL = f32(real("EMERGENCY_DECEL"))
PID_OUT_MAX = f32(real("PID_OUT_MAX"))
PWM_SCALE = f32(real("PWM_SCALE"))
KP_R = f32(real("KP_R"))
KI_R = f32(real("KI_R"))
KD_R = f32(real("KD_R"))
KP_L = f32(real("KP_L"))
KI_L = f32(real("KI_L"))
KD_L = f32(real("KD_L"))
STILL_SPEED = f32(real("STILL_SPEED"))
STILL_TICKS = integer("STILL_TICKS")

# Pivot (caster swivel)
PIVOT_SPEED = f32(real("PIVOT_SPEED"))
PIVOT_THRESHOLD = f32(real("PIVOT_THRESHOLD"))
PIVOT_START_SPEED = f32(real("PIVOT_START_SPEED"))

# PPM
PPM_CHANNELS = integer("PPM_CHANNELS")
PPM_NEUTRAL = integer("PPM_NEUTRAL")
PPM_SPAN = integer("PPM_SPAN")
PPM_DEADBAND = integer("PPM_DEADBAND")
PPM_VALID_MIN = integer("PPM_VALID_MIN")
PPM_VALID_MAX = integer("PPM_VALID_MAX")
PPM_MAX_WHEEL = f32(real("PPM_MAX_WHEEL"))
PPM_FWD_CHANNEL = integer("PPM_FWD_CHANNEL")
PPM_TURN_CHANNEL = integer("PPM_TURN_CHANNEL")

# Pins (Arduino Mega 2560 numbering)
PIN_ENC_L_A = integer("PIN_ENC_L_A")
PIN_ENC_L_B = integer("PIN_ENC_L_B")
PIN_ENC_R_A = integer("PIN_ENC_R_A")
PIN_ENC_R_B = integer("PIN_ENC_R_B")
PIN_PWM_L = integer("PIN_PWM_L")
PIN_PWM_R = integer("PIN_PWM_R")
PIN_DIR_L = integer("PIN_DIR_L")
PIN_DIR_R = integer("PIN_DIR_R")
PIN_RELAY = integer("PIN_RELAY")
PIN_BRAKE = integer("PIN_BRAKE")
PIN_BRAKE_STATUS = integer("PIN_BRAKE_STATUS")
PIN_PUSH = integer("PIN_PUSH")
PIN_INHIBIT_1 = integer("PIN_INHIBIT_1")
PIN_INHIBIT_2 = integer("PIN_INHIBIT_2")

# Fault detection (EVT:FAULT; docs/safety.md)
FAULT_STALL_PWM = integer("FAULT_STALL_PWM")
FAULT_STALL_PWM_STANDING = integer("FAULT_STALL_PWM_STANDING")
FAULT_STANDING_SPEED = f32(real("FAULT_STANDING_SPEED"))
FAULT_STALL_TICKS = integer("FAULT_STALL_TICKS")
FAULT_STALL_TICKS_TURNING = integer("FAULT_STALL_TICKS_TURNING")
FAULT_STALL_TICKS_LOADED = integer("FAULT_STALL_TICKS_LOADED")
FAULT_REVERSE_SPEED = f32(real("FAULT_REVERSE_SPEED"))
FAULT_REVERSE_TICKS = integer("FAULT_REVERSE_TICKS")
FAULT_REVERSE_APPROACH = f32(real("FAULT_REVERSE_APPROACH"))
FAULT_RUNAWAY_PWM = integer("FAULT_RUNAWAY_PWM")
FAULT_RUNAWAY_GAIN = f32(real("FAULT_RUNAWAY_GAIN"))
FAULT_RUNAWAY_TICKS = integer("FAULT_RUNAWAY_TICKS")
FAULT_EFFORT_PWM = integer("FAULT_EFFORT_PWM")
FAULT_EFFORT_SHORTFALL = f32(real("FAULT_EFFORT_SHORTFALL"))
FAULT_EFFORT_SHORTFALL_MOTOR = f32(real("FAULT_EFFORT_SHORTFALL_MOTOR"))
FAULT_EFFORT_LEAD = f32(real("FAULT_EFFORT_LEAD"))
FAULT_EFFORT_OVERRUN = f32(real("FAULT_EFFORT_OVERRUN"))
FAULT_EFFORT_EMF = f32(real("FAULT_EFFORT_EMF"))
FAULT_EFFORT_MAX = f32(real("FAULT_EFFORT_MAX"))
FAULT_EFFORT_LEAD_PWM = f32(real("FAULT_EFFORT_LEAD_PWM"))
FAULT_EFFORT_LAG = f32(real("FAULT_EFFORT_LAG"))
FAULT_EFFORT_TICKS = integer("FAULT_EFFORT_TICKS")
FAULT_ILLEGAL_PER_TICK = integer("FAULT_ILLEGAL_PER_TICK")
STORM_EDGES = integer("STORM_EDGES")
STORM_COMPARE = integer("STORM_COMPARE")
HW_WATCHDOG = integer("HW_WATCHDOG")
BRAKE_DONE_SPEED = f32(real("BRAKE_DONE_SPEED"))

# The parking brake (brake_fitted 1)
BRAKE_FITTED = integer("BRAKE_FITTED")
BRAKE_ACTIVE_TICKS = integer("BRAKE_ACTIVE_TICKS")
BRAKE_ENGAGE_TICKS = integer("BRAKE_ENGAGE_TICKS")
BRAKE_PRELOAD_TICKS = integer("BRAKE_PRELOAD_TICKS")
BRAKE_RELEASE_TICKS = integer("BRAKE_RELEASE_TICKS")
BRAKE_STATUS_TICKS = integer("BRAKE_STATUS_TICKS")
PUSH_SPEED = f32(real("PUSH_SPEED"))

# The motors' heat, estimated (docs/safety.md, "Motor heat")
THERMAL_AMBIENT = f32(real("THERMAL_AMBIENT"))
THERMAL_RESISTANCE = f32(real("THERMAL_RESISTANCE"))
THERMAL_CAPACITY = f32(real("THERMAL_CAPACITY"))
THERMAL_EMF = f32(real("THERMAL_EMF"))
THERMAL_LOSS = f32(real("THERMAL_LOSS"))
THERMAL_ROLLBACK_TEMP = f32(real("THERMAL_ROLLBACK_TEMP"))
THERMAL_HYSTERESIS = f32(real("THERMAL_HYSTERESIS"))
THERMAL_CUTOFF_TEMP = f32(real("THERMAL_CUTOFF_TEMP"))
THERMAL_EFFORT_MIN = f32(real("THERMAL_EFFORT_MIN"))
THERMAL_SHARE_MIN = f32(real("THERMAL_SHARE_MIN"))
#: What the sketch's constant expressions fold to (each exact in binary32).
THERMAL_ROLLBACK_SPAN = f32(THERMAL_CUTOFF_TEMP - THERMAL_ROLLBACK_TEMP)
THERMAL_ROLLBACK_END = f32(THERMAL_ROLLBACK_TEMP - THERMAL_HYSTERESIS)
THERMAL_EFFORT_SPAN = f32(real("FAULT_EFFORT_MAX") - THERMAL_EFFORT_MIN)
THERMAL_SHARE_SPAN = f32(1.0 - THERMAL_SHARE_MIN)
# The drive limits (docs/safety.md, "Drive limits")
DRIVE_SPEED_MIN = f32(real("DRIVE_SPEED_MIN"))
DRIVE_SPEED_MAX = f32(real("DRIVE_SPEED_MAX"))
DRIVE_ACCEL_MIN = f32(real("DRIVE_ACCEL_MIN"))
DRIVE_ACCEL_MAX = f32(real("DRIVE_ACCEL_MAX"))
TURN_SPEED_MIN = f32(real("TURN_SPEED_MIN"))
TURN_SPEED_MAX = f32(real("TURN_SPEED_MAX"))
TURN_ACCEL_MIN = f32(real("TURN_ACCEL_MIN"))
TURN_ACCEL_MAX = f32(real("TURN_ACCEL_MAX"))
TURN_AT_SPEED = f32(real("TURN_AT_SPEED"))
PROFILE_COUNT = integer("PROFILE_COUNT")
PROFILE = integer("PROFILE")
PROFILE_MAX = integer("PROFILE_MAX")
#: What the sketch's constant expression folds to: half the wheelbase, m.
HALF_WHEELBASE = f32(WHEELBASE * 0.5)
#: rad/s^2: a wheel's ramp at the default drive_accel and drive_decel (``wheel_rate``),
#: past ACCEL_MAX.
DRIVE_RATE_MAX = div(DRIVE_ACCEL_MAX, WHEEL_RADIUS)

# The supply, measured, and the low battery (docs/safety.md, "The battery")
PIN_SUPPLY = integer("PIN_SUPPLY")
SUPPLY_DIVIDER = f32(real("SUPPLY_DIVIDER"))
SUPPLY_VOLTS_PER_COUNT = f32(real("SUPPLY_VOLTS_PER_COUNT"))
SUPPLY_FILTER = f32(real("SUPPLY_FILTER"))
BATTERY_LOW_V = f32(real("BATTERY_LOW_V"))
BATTERY_HYSTERESIS = f32(real("BATTERY_HYSTERESIS"))
BATTERY_CUTOFF_V = f32(real("BATTERY_CUTOFF_V"))
BATTERY_SHARE_MIN = f32(real("BATTERY_SHARE_MIN"))
#: What the sketch's constant expressions fold to (each exact in binary32).
BATTERY_SPAN = f32(BATTERY_LOW_V - BATTERY_CUTOFF_V)
BATTERY_LOW_END = f32(BATTERY_LOW_V + BATTERY_HYSTERESIS)
BATTERY_SHARE_SPAN = f32(1.0 - BATTERY_SHARE_MIN)
#: The ADC count of a 24 V supply (datasheet rounding): what a tick reads when a caller
#: gives it no supply (``Firmware.tick``'s default).
SUPPLY_NOMINAL_COUNTS = round(24.0 / SUPPLY_VOLTS_PER_COUNT)

# The motors' currents, measured, and the stall timeout
PIN_CURRENT_L = integer("PIN_CURRENT_L")
PIN_CURRENT_R = integer("PIN_CURRENT_R")
CURRENT_ZERO_COUNTS = integer("CURRENT_ZERO_COUNTS")
CURRENT_AMPS_PER_COUNT = f32(real("CURRENT_AMPS_PER_COUNT"))
STALL_CURRENT = f32(real("STALL_CURRENT"))
STALL_CREEP_COUNTS = integer("STALL_CREEP_COUNTS")
STALL_HELD_OUTPUT = f32(real("STALL_HELD_OUTPUT"))
STALL_TIMEOUT = f32(real("STALL_TIMEOUT"))
STALL_TIMEOUT_MIN = f32(real("STALL_TIMEOUT_MIN"))
STALL_TIMEOUT_MAX = f32(real("STALL_TIMEOUT_MAX"))
CURRENT_SENSE_MAX = f32(real("CURRENT_SENSE_MAX"))
MOTOR_AMPS_PER_DUTY = f32(real("MOTOR_AMPS_PER_DUTY"))
STANDING_DRAW_SHARE = f32(real("STANDING_DRAW_SHARE"))
MOTOR_DRAW_MIN = f32(real("MOTOR_DRAW_MIN"))
MOTOR_DRAW_SHARE = f32(real("MOTOR_DRAW_SHARE"))
HOLD_DEADBAND_COUNTS = integer("HOLD_DEADBAND_COUNTS")
HOLD_GAIN = integer("HOLD_GAIN")
HOLD_PWM_MAX = integer("HOLD_PWM_MAX")
ROLLAWAY_COUNTS = integer("ROLLAWAY_COUNTS")
OVERSPEED_PWM = integer("OVERSPEED_PWM")
OVERSPEED_MARGIN = f32(real("OVERSPEED_MARGIN"))
OVERSPEED_GAIN = f32(real("OVERSPEED_GAIN"))
OVERSPEED_TICKS = integer("OVERSPEED_TICKS")
OVERSPEED_ONE_TICKS = integer("OVERSPEED_ONE_TICKS")
GRADE_PWM = integer("GRADE_PWM")
GRADE_STALL = f32(real("GRADE_STALL"))
# Modes (printed as MODE:WHEEL / CMDVEL / PPM)
MODE_WHEEL = integer("MODE_WHEEL")
MODE_CMDVEL = integer("MODE_CMDVEL")
MODE_PPM = integer("MODE_PPM")

# Ranges of the runtime parameters (get:/set:; the defaults are the constants above)
# Parameters in EEPROM
EEPROM_SIZE = integer("EEPROM_SIZE")
EEPROM_PARAMS_ADDR = integer("EEPROM_PARAMS_ADDR")
EEPROM_LAYOUT = integer("EEPROM_LAYOUT")

# The feedback line's form (feedback_form)
FEEDBACK_FORM = integer("FEEDBACK_FORM")
FEEDBACK_FORM_MAX = integer("FEEDBACK_FORM_MAX")
BRAKE_FITTED_MAX = integer("BRAKE_FITTED_MAX")

GAIN_P_MIN = f32(real("GAIN_P_MIN"))
GAIN_P_MAX = f32(real("GAIN_P_MAX"))
GAIN_I_MIN = f32(real("GAIN_I_MIN"))
GAIN_I_MAX = f32(real("GAIN_I_MAX"))
GAIN_D_MAX = f32(real("GAIN_D_MAX"))
MAX_WHEEL_MIN = f32(real("MAX_WHEEL_MIN"))
ACCEL_MIN = f32(real("ACCEL_MIN"))
ACCEL_MAX = f32(real("ACCEL_MAX"))
DECEL_MIN = f32(real("DECEL_MIN"))
DECEL_MAX = f32(real("DECEL_MAX"))
WATCHDOG_MIN_MS = integer("WATCHDOG_MIN_MS")
WATCHDOG_MAX_MS = integer("WATCHDOG_MAX_MS")

ONE_MINUS_ALPHA = f32(1.0 - ALPHA)   # folded by gcc: 1.0f - 0.8f is exact
MODE_NAMES = {MODE_WHEEL: "WHEEL", MODE_CMDVEL: "CMDVEL", MODE_PPM: "PPM"}

HIGH = 1
LOW = 0
