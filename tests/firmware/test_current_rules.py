"""What the motors' currents say below the current limit (docs/safety.md, "What the
currents say"): a wheel that stands by its current is not a stalled encoder below full
torque, and a motor that draws what its effort calls for is not a dead one. The rules
worked by hand on the port, then each injected on both backends (the compiled firmware
in simavr, its current senses on A1 and A2, replayed on the port in lock step with no
mismatch)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.recordings import COUNTS_PER_RAD, board_lines, every, recorded, tick_states, turning
from wcdrive.boards.current_sense import current_millivolts
from wcdrive.firmware import constants as C
from wcdrive.firmware.motor_rule import motor_draws, motor_silent
from wcdrive.firmware.stall import sense_amps, stands_by_current
from wcdrive.hil.current_traces import stand_still
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.plant.params import ChairParams


# ---- the rules, by hand ------------------------------------------------------------------
def test_the_amps_a_duty_drives_through_a_standing_armature_are_the_plants() -> None:
    """MOTOR_AMPS_PER_DUTY: 24 V / 255 a duty over the armature's 0.3 ohm, 0.3137 A; a
    standing wheel at duty 26 draws 8.16 A, at 41 12.86 A (the driver's 13 A limit is
    duty 41.4: FAULT_STALL_PWM_STANDING's full torque)."""
    p = ChairParams()
    assert C.MOTOR_AMPS_PER_DUTY == pytest.approx(p.supply_voltage / 255 / p.armature_resistance, rel=1e-4)
    assert 26 * C.MOTOR_AMPS_PER_DUTY == pytest.approx(8.156, abs=1e-3)
    assert p.current_limit / C.MOTOR_AMPS_PER_DUTY == pytest.approx(41.44, abs=0.01)


def test_a_wheel_stands_by_its_current_at_three_quarters_of_its_stand() -> None:
    """Duty 30 toward a forward setpoint, the partner short of its own (0.5 of 2 rad/s):
    a stand draws 9.41 A; 0.75 of it, 7.06 A (count 512 + 58 = 7.08 A) stands, 57
    (6.96 A) does not; backward alike with the current's sign; a braking current, a duty
    against the setpoint or no setpoint never stand, nor a wheel whose partner keeps 0.8
    of its setpoint (blocked alone: locked, or its encoder cut); 1 A at the least."""
    assert sense_amps(512 + 58) >= 0.75 * 30 * C.MOTOR_AMPS_PER_DUTY > sense_amps(512 + 57)
    short = (2.0, 0.5)                                         # the partner's setpoint, its speed
    assert stands_by_current(30, C.HIGH, 1.0, 512 + 58, *short)
    assert not stands_by_current(30, C.HIGH, 1.0, 512 + 57, *short)
    assert stands_by_current(30, C.LOW, -1.0, 512 - 58, -2.0, -0.5)
    assert not stands_by_current(30, C.LOW, -1.0, 512 + 58, -2.0, -0.5)    # braking
    assert not stands_by_current(30, C.HIGH, 1.0, 512 - 58, *short)         # braking
    assert not stands_by_current(30, C.LOW, 1.0, 512 - 58, *short)          # driven against its setpoint
    assert not stands_by_current(30, C.HIGH, 0.0, 512 + 58, *short)         # no setpoint
    assert not stands_by_current(30, C.HIGH, 1.0, 512 + 58, 2.0, 1.61)      # the partner keeps 0.8
    assert stands_by_current(30, C.HIGH, 1.0, 512 + 58, 2.0, 1.59)
    assert stands_by_current(30, C.HIGH, 1.0, 512 + 58, -2.0, -1.59)        # a spin: its own way
    # 1 A at the least: duty 2 asks 0.47 A of a stand, 0.98 A (8 counts) is not enough
    assert not stands_by_current(2, C.HIGH, 1.0, 512 + 8, *short)
    assert stands_by_current(2, C.HIGH, 1.0, 512 + 9, *short)
    assert not stands_by_current(0, C.HIGH, 1.0, 512, *short)


def test_a_turning_wheel_at_the_same_duty_draws_less_than_a_standing_one() -> None:
    """The bound the share sets, worked from the plant's motor: at duty 41 and 24 V a
    wheel that draws 0.75 of its stand's current has a back-EMF of a quarter of its
    duty's volts or less: 0.73 rad/s (0.11 m/s at the rim); a cut encoder's wheel turning
    at 1.0 rad/s draws 66 % of a stand's current and does not stand."""
    p = ChairParams()
    ke_g = p.motor_constant * p.gear_ratio
    volts = 41 * 24.0 / 255

    def drawn(speed: float) -> float:
        return (volts - ke_g * speed) / p.armature_resistance

    fastest = (1 - C.STANDING_DRAW_SHARE) * volts / ke_g
    assert fastest == pytest.approx(0.73, abs=0.01)
    assert fastest * p.wheel_radius == pytest.approx(0.112, abs=1e-3)
    assert drawn(fastest) == pytest.approx(C.STANDING_DRAW_SHARE * drawn(0.0), rel=1e-9)
    assert drawn(1.0) / drawn(0.0) == pytest.approx(0.66, abs=0.01)
    assert drawn(1.0) / drawn(0.0) < C.STANDING_DRAW_SHARE


def test_a_motor_draws_half_the_current_its_effort_calls_for_or_more() -> None:
    """A wheel at 5 rad/s toward a forward setpoint at duty 100: its effort is
    100 - 14.5 x 5 = 27.5 duty, 8.63 A through the armature; half of it, 4.31 A (count
    512 + 36 = 4.39 A) draws, 35 (4.27 A) does not. Braking (duty 50: -22.5, -7.06 A):
    -3.53 A or more that way. Backward alike. The effort within the driver's current
    limit (``effort_of``): a motor at its limit works. 1 A at the least; not for a wheel slower
    than 0.3 rad/s its way (a stand is the stall rules') or counting nothing this tick,
    nor one that reads a speed against its setpoint (a reversed encoder turning toward
    it), nor without a setpoint."""
    def draws(pwm: int, direction: int, setpoint: float, speed: float, count: int, delta: int = 20) -> bool:
        return motor_draws(pwm, direction, setpoint, speed, delta, count)

    assert 0.5 * 27.5 * C.MOTOR_AMPS_PER_DUTY == pytest.approx(4.313, abs=1e-3)
    assert draws(100, C.HIGH, 1.0, 5.0, 512 + 36) and not draws(100, C.HIGH, 1.0, 5.0, 512 + 35)
    assert draws(50, C.HIGH, 1.0, 5.0, 512 - 29) and not draws(50, C.HIGH, 1.0, 5.0, 512 - 28)
    assert draws(100, C.LOW, -1.0, -5.0, 512 - 36) and not draws(100, C.LOW, -1.0, -5.0, 512 + 36)
    assert not draws(100, C.HIGH, 1.0, 5.0, 512 - 36)                 # against its effort
    # a small effort (duty 75: 2.5, 0.78 A): 1 A at the least
    assert not draws(75, C.HIGH, 1.0, 5.0, 512 + 8) and draws(75, C.HIGH, 1.0, 5.0, 512 + 9)
    # at the driver's limit: duty 200 at 5 rad/s asks 127.5, within FAULT_EFFORT_MAX 41:
    # half of 12.86 A, 6.43 A; a motor at its 13 A limit draws it (unclamped, 20 A)
    assert draws(200, C.HIGH, 1.0, 5.0, 512 + 106) and draws(200, C.HIGH, 1.0, 5.0, 512 + 53)
    assert not draws(200, C.HIGH, 1.0, 5.0, 512 + 52)
    assert not draws(100, C.HIGH, 1.0, 0.29, 512 + 60)                # standing
    assert not draws(100, C.HIGH, 1.0, -5.0, 512 + 60)                # reads against its setpoint
    assert not draws(100, C.HIGH, 0.0, 5.0, 512 + 60)
    # a wheel that counts nothing this tick (just locked, its filtered speed lagging)
    assert not draws(100, C.HIGH, 1.0, 5.0, 512 + 60, delta=0)


# ---- both backends -------------------------------------------------------------------------
def _slowing(until: float, mirrored: bool, speed: float, at: float, share: float) -> EdgeTrain:
    """A wheel at rest until 0.3 s, at ``speed`` rad/s until ``at``, then at ``share`` of
    it (dragged)."""
    t = np.linspace(0.0, until, 4000)
    angle = np.where(t < 0.3, 0.0, np.where(t < at, (t - 0.3) * speed,
                                            (at - 0.3) * speed + (t - at) * speed * share))
    return edges_from_trajectory(t, 0.5 + (-1 if mirrored else 1) * angle * COUNTS_PER_RAD)


def _drive(duration: float, speed: float, left: str, right: str, amps: float,
           left_amps: float = 3.0) -> Recording:
    """A neutral command, then rp/lp ``speed`` every 0.1 s, both wheels turning at it;
    from 1.0 s each wheel as its word says: "turns" on, "stands", "creeps" (0.4 % of it: a
    count every two or three ticks at 1.2 rad/s), is "dragged" (turns at 40 % of it),
    "slowed" (84 %) or "carried" (110 %); the right motor drawing ``amps`` A and the left
    one ``left_amps`` (working) from 0.06 s before."""
    command = b"rp%05.2f,lp%05.2f\n" % (speed, speed)
    writes = [(0.02, b"rp0,lp0,\n"), *every(command, 0.2, duration - 0.05)]
    encoders = {}
    for side, how in (("left", left), ("right", right)):
        mirrored = side == "left"
        encoders[side] = {"turns": turning(duration, mirrored, speed),
                          "stands": stand_still(turning(duration, mirrored, speed), 1.0, duration),
                          "creeps": _slowing(duration, mirrored, speed, 1.0, 0.004),
                          "dragged": _slowing(duration, mirrored, speed, 1.0, 0.4),
                          "slowed": _slowing(duration, mirrored, speed, 1.0, 0.84),
                          "carried": _slowing(duration, mirrored, speed, 1.0, 1.1)}[how]
    return recorded(Trace(duration=duration, serial=sorted(writes), encoders=encoders,
                          currents=[(0.94, "right", current_millivolts(amps)),
                                    (0.94, "left", current_millivolts(left_amps))]))


def _fault_at(rec: Recording) -> float:
    return next(t for t, a in tick_states(rec) if a["faultFlags"])


@pytest.mark.simavr
def test_a_wheel_creeping_by_its_current_on_a_loaded_chair_is_no_stall() -> None:
    """1.2 rad/s asked; from 1.0 s the right wheel creeps (a count every two or three
    ticks), its motor drawing 10 A (a stand's current up to duty 42), and the left one
    turns at 40 % (the chair is loaded): for the 0.8 s its duty climbs from 26 toward
    full torque nothing latches, its count-less runs 2 ticks long at the most. Red
    without the rule: ENC_STALL_R at the first 2-tick run at duty 26 (as the envelope's
    drive 176 did)."""
    rec = _drive(1.8, 1.2, "dragged", "creeps", 10.0)
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    ticks = [a for t, a in tick_states(rec) if t > 1.1]
    assert max(a["stallTicksR"] for a in ticks) in (2, 3)
    assert 26 <= max(a["pwmR"] for a in ticks) < C.FAULT_STALL_PWM_STANDING


@pytest.mark.simavr
def test_a_wheel_standing_by_its_current_on_a_loaded_chair_stalls_after_six_ticks() -> None:
    """The same, the right wheel standing (locked, or its encoder cut and the wheel held):
    ENC_STALL_R after 6 count-less ticks at duty 26, 0.15 s later than without the
    rule (2 ticks)."""
    rec = _drive(2.0, 1.2, "dragged", "stands", 10.0)
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,ENC_STALL_R"]
    assert 1.3 < _fault_at(rec) < 1.4


@pytest.mark.simavr
@pytest.mark.parametrize(("left", "amps"), [("dragged", 2.0), ("turns", 10.0)],
                         ids=["draws-little", "blocked-alone"])
def test_a_standing_wheel_drawing_little_or_blocked_alone_is_a_stall_at_a_tenth_of_full_duty(
        left: str, amps: float) -> None:
    """The same stand, the motor drawing 2 A (a cut encoder's wheel that turns, its
    back-EMF taking the current off); or drawing 10 A while the left wheel keeps its
    setpoint (the right one blocked alone: locked, or its encoder cut and the wheel
    held): ENC_STALL_R two ticks after its duty reaches 26, as before the rule."""
    rec = _drive(1.5, 1.2, left, "stands", amps)
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,ENC_STALL_R"]
    assert 1.1 < _fault_at(rec) < 1.2


@pytest.mark.simavr
def test_a_dragged_wheel_whose_motor_draws_is_its_load_not_a_dead_motor() -> None:
    """3 rad/s asked; from 1.0 s the right wheel turns at 40 % of it while its partner
    keeps it, its duty winding up without a gain (effort without progress, leading its
    partner's), its motor drawing 12.5 A, about its current limit (half or more of what
    its effort, within that limit, calls for, at any duty): no fault as the duty climbs
    past 150. Red without the rule: MOTOR_R."""
    rec = _drive(4.5, 3.0, "turns", "dragged", 12.5)
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    ticks = tick_states(rec)
    assert max(a["effortTicksR"] for _, a in ticks) >= C.FAULT_EFFORT_TICKS
    assert max(a["pwmR"] for _, a in ticks) > 150


@pytest.mark.simavr
@pytest.mark.parametrize("amps", [0.0, 5.0], ids=["dead", "short-of-its-effort"])
def test_a_dragged_wheel_whose_motor_draws_nothing_or_too_little_is_a_dead_motor(amps: float) -> None:
    """The same drag, the motor drawing nothing (an open winding, a dead driver), or
    5 A as its duty climbs past 49 (less than half of what its effort calls for): MOTOR_R,
    as before the rule."""
    rec = _drive(2.5, 3.0, "turns", "dragged", amps)
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,MOTOR_R"]


@pytest.mark.simavr
def test_a_working_motor_is_not_blamed_its_silent_partner_is() -> None:
    """3 rad/s asked; from 1.0 s the left wheel turns at 40 % of it, its duty winding up
    without a gain and its motor drawing 12.5 A (it works), while the right wheel keeps
    its setpoint at duty 7, which at 3 rad/s calls for 11 A of braking, and its motor
    draws nothing: an open winding carried by the chair (the envelope's dead motors going
    down a band). MOTOR_R, the silent one. Red without the rule: nothing latches (the
    working left motor is not blamed); before the currents: MOTOR_L, the healthy one."""
    rec = _drive(2.5, 3.0, "dragged", "turns", 0.0, left_amps=12.5)
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,MOTOR_R"]


def test_a_motor_is_silent_below_1_amp_where_its_duty_and_speed_call_for_3() -> None:
    """Duty 7 forward at 3 rad/s calls for (7 - 43.5) x 0.3137 = -11.4 A; drawing 0.98 A
    (count 512 + 8) either way it is silent, 1.10 A (9) not. Duty 50 at 3.3 rad/s calls
    for 0.67 A: never silent. Backward alike."""
    assert motor_silent(7, C.HIGH, 3.0, 512) and motor_silent(7, C.HIGH, 3.0, 512 + 8)
    assert motor_silent(7, C.HIGH, 3.0, 512 - 8) and not motor_silent(7, C.HIGH, 3.0, 512 - 9)
    assert not motor_silent(50, C.HIGH, 3.3, 512)
    assert motor_silent(7, C.LOW, -3.0, 512) and not motor_silent(50, C.LOW, -3.3, 512)
    # the 3 A bracketed: standing, duty 10 calls for 3.14 A (silent at 0 A), duty 9 for
    # 2.82 A (not); duty 50 at 2.76 rad/s for 3.13 A, at 2.80 for 2.95 A
    assert motor_silent(10, C.HIGH, 0.0, 512) and not motor_silent(9, C.HIGH, 0.0, 512)
    assert motor_silent(10, C.LOW, 0.0, 512) and not motor_silent(9, C.LOW, 0.0, 512)
    assert motor_silent(50, C.HIGH, 2.76, 512) and not motor_silent(50, C.HIGH, 2.80, 512)
