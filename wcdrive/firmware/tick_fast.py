"""The control tick's common case in C (``csrc/tick_fast.c``), for speed.

``tick(state, now, count_l, count_r, illegal_l, illegal_r, storm_l, storm_r, rx_lost, inputs,
supply, current_l, current_r)``
returns the bytes ``control.control_tick`` would send, having changed ``state`` as it
would, or None having changed nothing: then the Python tick, the reference, runs
(``Firmware.tick`` does that). The C path declines everything but the common case: a
fault that latches, the watchdog firing, a tick that waits for neutral, a drive limit
set away from its default (``wcdrive.firmware.drive``), any binary32
result that is not an ordinary number (``wcdrive.avr.f32`` computes those bit by bit as
avr-libc does), a field of an unexpected type. tests/firmware/test_tick_fast.py holds it to the Python tick.

``fast`` is None (the Python tick only) without a compiler, Python's headers or a
writable cache, or with ``WCDRIVE_PURE_TICK=1`` (or ``WCDRIVE_PURE_F32=1``) in the
environment.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from types import ModuleType

from wcdrive._util import native
from wcdrive.avr.arduino_print import _rounding
from wcdrive.firmware import brake, control, motion
from wcdrive.firmware import constants as C
from wcdrive.firmware.state import FirmwareState

_SOURCE = Path(__file__).resolve().parent / "csrc" / "tick_fast.c"

#: The constants the C tick uses, by name (``_bind`` checks each is there and typed).
_FLOATS = ("ALPHA", "ONE_MINUS_ALPHA", "CPR", "TWO_PI", "PID_OUT_MAX", "PWM_SCALE", "STILL_SPEED",
           "BRAKE_DONE_SPEED", "FAULT_STANDING_SPEED", "FAULT_REVERSE_SPEED", "FAULT_REVERSE_APPROACH",
           "FAULT_RUNAWAY_GAIN",
           "FAULT_EFFORT_SHORTFALL_MOTOR", "FAULT_EFFORT_LEAD",
           "FAULT_EFFORT_OVERRUN", "PIVOT_START_SPEED", "PIVOT_SPEED",
           "OVERSPEED_MARGIN", "OVERSPEED_GAIN", "THERMAL_EMF", "FAULT_EFFORT_MAX", "THERMAL_AMBIENT",
           "THERMAL_RESISTANCE", "THERMAL_CAPACITY", "THERMAL_LOSS", "THERMAL_ROLLBACK_TEMP",
           "SUPPLY_VOLTS_PER_COUNT", "SUPPLY_FILTER", "BATTERY_LOW_V", "DRIVE_SPEED_MAX", "DRIVE_ACCEL_MAX",
           "TURN_SPEED_MAX", "TURN_ACCEL_MAX", "TURN_AT_SPEED", "DRIVE_RATE_MAX", "WHEEL_RADIUS", "WHEELBASE",
           "CURRENT_AMPS_PER_COUNT", "STALL_CURRENT", "CURRENT_SENSE_MAX", "MOTOR_AMPS_PER_DUTY",
           "STANDING_DRAW_SHARE", "FAULT_EFFORT_SHORTFALL", "MOTOR_DRAW_MIN")
_INTS = ("CONTROL_PERIOD_MS", "TX_CREDIT_MAX", "TX_CREDIT_PER_MS", "FAULT_STALL_PWM",
         "FAULT_STALL_PWM_STANDING",
         "FAULT_STALL_TICKS",
         "FAULT_STALL_TICKS_TURNING", "FAULT_STALL_TICKS_LOADED", "FAULT_REVERSE_TICKS", "FAULT_RUNAWAY_PWM",
         "FAULT_RUNAWAY_TICKS",
         "FAULT_EFFORT_PWM", "FAULT_EFFORT_TICKS", "FAULT_ILLEGAL_PER_TICK",
         "STILL_TICKS", "PIVOT_TICKS", "HIGH", "LOW", "HOLD_DEADBAND_COUNTS", "OVERSPEED_PWM",
         "OVERSPEED_TICKS", "CURRENT_ZERO_COUNTS", "STALL_CREEP_COUNTS")


def _constants() -> dict[str, float | int]:
    out: dict[str, float | int] = {name: float(getattr(C, name)) for name in _FLOATS}
    out.update({name: int(getattr(C, name)) for name in _INTS})
    out.update(ROUNDING_2=_rounding(2), PIVOT_NONE=motion.PIVOT_NONE,
               PIVOT_STOPPING=motion.PIVOT_STOPPING, PIVOT_ROTATING=motion.PIVOT_ROTATING,
               FAULTS_UNTRUSTED_L=control.FAULTS_UNTRUSTED_L, FAULTS_UNTRUSTED_R=control.FAULTS_UNTRUSTED_R,
               BRAKE_RELEASED=brake.BRAKE_RELEASED)
    return out


def pure() -> bool:
    """Whether the environment asks for the Python tick only."""
    names = ("WCDRIVE_PURE_TICK", "WCDRIVE_PURE_F32")
    return any(os.environ.get(name, "") not in ("", "0") for name in names)


def load_fast() -> ModuleType | None:
    """The C tick bound to ``FirmwareState`` and the constants: the one the install built,
    else built on first use (``wcdrive._util.native``); None when it cannot be had or
    ``pure()``."""
    if pure():
        native.record("control tick", "Python (WCDRIVE_PURE_TICK)")
        return None
    how = "built at install"
    try:
        module = native.prebuilt("wcdrive.firmware._tick_fast", _SOURCE)
        if module is None:
            module = native.load_extension(_SOURCE, "_tick_fast", ("-O2", "-ffp-contract=off"))
            how = "built at first use"
        module._bind(FirmwareState, _constants(), {k: v.encode() for k, v in C.MODE_NAMES.items()})
    except (native.BuildError, OSError, TypeError, ValueError) as exc:
        # OSError: no writable cache, for one; TypeError/ValueError: _bind refused what it
        # was given (a state type or constant it cannot use)
        logging.getLogger(__name__).warning("the control tick in pure Python (slower): %s", exc)
        native.record("control tick", f"Python ({exc})".splitlines()[0])
        return None
    native.record("control tick", how)
    return module


fast = load_fast()
