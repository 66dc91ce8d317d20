"""The hold's rules on the port, tick by tick (PROTOCOL.md, "Hold and rollaway"): the
law, the reference that follows a wheel still slowing, the latch, EVT:ROLLAWAY once
per hold and the hardest brake after it. The compiled firmware is held to the same
bits by the lock-step runs (``wcdrive verify``'s traces reach the hold, its duties
and rollaways) and by tests/sim/test_hill_hold.py."""

from __future__ import annotations

from wcdrive.firmware import constants as C
from wcdrive.firmware.control import FAULT_DRIVER, FAULT_STALL_L, control_tick
from wcdrive.firmware.motors import hold_duty
from wcdrive.firmware.state import FirmwareState


def test_the_law() -> None:
    db, top = C.HOLD_DEADBAND_COUNTS, C.HOLD_PWM_MAX
    assert [hold_duty(e, 0) for e in (0, db, -db)] == [0, 0, 0]
    assert hold_duty(db + 1, 0) == hold_duty(-db - 1, 0) == C.HOLD_GAIN
    assert hold_duty(db + 33, 0) == 33 * C.HOLD_GAIN
    assert hold_duty(db + top // C.HOLD_GAIN, 0) == top == hold_duty(2**31 - 1, 0) == hold_duty(-2**31, 0)
    assert hold_duty(db + 1, 1) == top and hold_duty(db, 1) == 0     # after a rollaway


def _ticks(s: FirmwareState, rights: list[int], lefts: list[int] | None = None) -> list[bytes]:
    outs = []
    for k, right in enumerate(rights):
        out = bytearray()
        control_tick(s, 50 * (k + 1), 0 if lefts is None else lefts[k], right, out)
        outs.append(bytes(out))
    return outs


def _coasting() -> FirmwareState:
    """Braked after an emergency ramp: parks at its first tick (slower than BRAKE_DONE_SPEED)."""
    return FirmwareState(emergencyStop=1, parked=0, holding=0, lastControlTime=0)


def test_the_reference_follows_a_wheel_still_slowing() -> None:
    """A wheel that parks still coasting (20, 15, 10, 5, 2 counts a tick) is held where
    it stops: duty 0 throughout."""
    s = _coasting()
    _ticks(s, [20, 35, 45, 50, 52, 52, 52])
    assert s.parked and s.holding and s.holdRefR == 52 and s.holdStepR == 0
    assert s.pwmR == 0


def test_the_reference_stays_once_the_wheel_speeds_up() -> None:
    """A wheel that speeds up after parking (a grade) is held where it began to: the
    reference stops following, the duty grows with the error, against it."""
    s = _coasting()
    _ticks(s, [20, 35, 65])
    assert s.holdRefR == 35 and s.holdStepR == 0
    assert (s.pwmR, s.dirR) == (30 - C.HOLD_DEADBAND_COUNTS, C.LOW)        # right: counts rise forward


def test_the_left_wheel_is_driven_the_mirrored_way() -> None:
    """The left wheel's counts fall going forward: pushed forward 40 counts, it is
    driven backward (DIR LOW), as the right one is pushed forward (counts rising)."""
    s = _coasting()
    _ticks(s, [0, 0, 0], lefts=[0, 0, -40])
    assert (s.pwmL, s.dirL) == (40 - C.HOLD_DEADBAND_COUNTS, C.LOW)
    assert (s.pwmR, s.dirR) == (0, C.HIGH)


def test_a_held_chair_stays_parked_when_pushed() -> None:
    """Moving faster than STILL_SPEED does not unpark a holding chair; a motion command does."""
    s = _coasting()
    _ticks(s, [0, 0, 0, 100, 200])
    assert s.parked and s.holding and s.stillTicks == 0


def test_rollaway_once_per_hold_then_the_hardest_brake() -> None:
    s = _coasting()
    outs = _ticks(s, [0, 0, C.ROLLAWAY_COUNTS, C.ROLLAWAY_COUNTS + 1, C.ROLLAWAY_COUNTS + 500,
                      C.ROLLAWAY_COUNTS + 500 - 170])
    events = [k for k, out in enumerate(outs) if b"EVT:ROLLAWAY\r\n" in out]
    assert events == [3]
    # 40 counts off the trailing reference: still the hardest
    assert s.holdRollaway and (s.pwmR, s.dirR) == (C.HOLD_PWM_MAX, C.LOW)
    assert not outs[2].count(b"EVT:")


def test_a_chair_pushed_far_is_braked_not_driven_back() -> None:
    """Pushed 5 cm (500 counts) past where it was held, the reference trails the wheel by
    ROLLAWAY_COUNTS + 1: let go, the hold drives it back at most that far (2 cm)."""
    s = _coasting()
    _ticks(s, [0, 0, 100, 300, 500])
    assert s.holdRefR == 500 - (C.ROLLAWAY_COUNTS + 1)
    _ticks(s, [500, 500])
    assert s.holdRefR == 500 - (C.ROLLAWAY_COUNTS + 1)


def test_a_fault_that_leaves_no_encoder_parks_at_duty_zero_without_the_hold() -> None:
    s = _coasting()
    _ticks(s, [0, 0, 100])
    assert s.pwmR > 0
    s.faultFlags = FAULT_DRIVER
    _ticks(s, [150])
    assert s.parked and not s.holding and (s.pwmR, s.pwmL) == (0, 0)


def test_after_a_fault_the_healthy_wheel_brakes_and_holds_and_the_faulty_one_mirrors_it() -> None:
    """ENC_STALL_L latched while the right wheel turns at 7.3 rad/s (300 counts a tick):
    the right wheel's PID brakes it along the emergency ramp, the left motor at duty 0;
    at rest the right wheel is held and the left mirrors its hold."""
    s = FirmwareState(emergencyStop=1, parked=0, holding=0, lastControlTime=0, filtVelR=7.3)
    s.faultFlags = FAULT_STALL_L
    rights = [300, 600, 900]
    _ticks(s, rights)
    assert not s.parked and not s.brakeReleased
    assert s.pwmR > 0 and s.dirR == C.LOW                     # braking the forward roll
    assert (s.pwmL, s.dirL) == (0, C.HIGH)
    # the wheel stops: parked, held; pushed on, both are driven back alike
    for k in range(12):
        control_tick(s, 50 * (4 + k), 0, 900, bytearray())
    assert s.parked and s.holding
    control_tick(s, 50 * 16, 0, 940, bytearray())
    assert (s.pwmR, s.dirR) == (40 - C.HOLD_DEADBAND_COUNTS, C.LOW)
    assert (s.pwmL, s.dirL) == (s.pwmR, s.dirR)
