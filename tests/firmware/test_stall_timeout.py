"""The motors' current senses and the stall timeout (docs/safety.md, "Stall timeout"):
the rules worked by hand on the port, then each condition injected on both backends (the
compiled firmware in simavr, its current senses on A1 and A2, replayed on the port in
lock step with no mismatch)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.recordings import COUNTS_PER_RAD, board_lines, every, recorded, tick_states, turning
from wcdrive.avr.f32 import f32
from wcdrive.boards.current_sense import current_millivolts
from wcdrive.boards.supply_sense import adc_counts
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.stall import current_sense_fault, held_at_limit, held_bounds, sense_amps
from wcdrive.hil.current_traces import stand_still
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.plant.params import ChairParams

#: The duty of a wheel held at its current limit.
HELD_DUTY = int(C.STALL_HELD_OUTPUT * C.PWM_SCALE)


# ---- the rules, by hand ------------------------------------------------------------------
def test_a_count_reads_its_amps_either_way() -> None:
    """40 mV/A at 5 V / 1024 a count: 0.1220703125 A a count from 512 (2.5 V), above it
    for a current that drives the wheel forward."""
    assert sense_amps(C.CURRENT_ZERO_COUNTS) == 0.0
    assert sense_amps(512 + 90) == -sense_amps(512 - 90) == pytest.approx(10.986328125, abs=0)
    assert sense_amps(512 + 91) == pytest.approx(11.108398438)       # the first past 11 A
    # what simavr's ADC makes of the mV a 12.5 A current puts on the pin (3000 mV: 613)
    assert current_millivolts(12.5) == 3000 and adc_counts(3000) == 613
    assert sense_amps(613) == pytest.approx(12.329101562)


def test_a_sense_past_30_amps_either_way_has_failed() -> None:
    """245 counts from 512 is 29.9 A, within; 246 is 30.03 A, a failed sense; a cut
    output (0 V, count 0) reads 62.5 A, one shorted to 5 V (1023) 62.4 A."""
    assert current_sense_fault(512 + 245, 512 - 245) == 0
    for left, right in ((512 + 246, 512), (512, 512 - 246), (0, 512), (512, 1023)):
        assert current_sense_fault(left, right) == 0x4000


def test_a_wheel_is_held_only_standing_driven_and_at_its_limit() -> None:
    """Held: the wheel 2 counts this tick at most (a tyre against a wall creeps), beside
    a partner that stands too or, in a spin (the setpoints of opposite signs), turns its
    own way at any speed (the chair pivots about the held wheel: up a grade at its limit,
    the pilot's spin back to its path); driven its setpoint's way at duty 42 or more, 11 A
    or more that way. Each condition alone taken away is not held: a partner that moves
    beside it on a straight run (a chair crawling up a grade at its limit, 14 counts a
    tick at 0.18 rad/s), or that turns this wheel's way in a spin, leaves a count-less
    wheel a stalled encoder, and a braking current (a wheel pushed downhill faster than
    its duty turns it) says nothing of a stand."""
    amps = 512 + 100                                   # 12.2 A

    def straight(delta: int, other_delta: int, pwm: int, way: int, setpoint: float, current: int) -> bool:
        return held_at_limit(delta, other_delta, pwm, way, setpoint, current, setpoint, 0.0)

    assert straight(0, 0, 42, C.HIGH, 2.0, amps)
    assert straight(0, 0, 42, C.LOW, -2.0, 512 - 100)                # backward: its current backward
    assert not straight(0, 0, 42, C.HIGH, 2.0, 512 - 100)            # braking: pushed faster than it drives
    assert not straight(0, 0, 42, C.LOW, -2.0, amps)                 # ...backward
    assert straight(2, -2, 42, C.HIGH, 2.0, amps)                    # creeping, 2 counts a tick
    assert not straight(3, 0, 42, C.HIGH, 2.0, amps)                 # moving
    assert not straight(0, 14, 42, C.HIGH, 2.0, amps)                # the partner moves
    assert not straight(0, -3, 42, C.HIGH, 2.0, amps)                # ...either way
    assert not straight(0, 0, 41, C.HIGH, 2.0, amps)                 # below full torque
    assert not straight(0, 0, 42, C.LOW, 2.0, amps)                  # driven against its setpoint
    assert not straight(0, 0, 42, C.HIGH, 0.0, amps)                 # no setpoint
    assert not straight(0, 0, 42, C.HIGH, 2.0, 512 + 90)             # 10.99 A
    # a spin: the partner's setpoint the other way
    assert held_at_limit(0, 90, 42, C.HIGH, 1.12, amps, -1.12, -1.14)      # it turns its own way
    assert held_at_limit(0, -90, 42, C.LOW, -1.12, 512 - 100, 1.12, 1.14)  # ...mirrored
    assert held_at_limit(0, 0, 42, C.HIGH, 1.12, amps, -1.12, 0.0)         # it stands
    assert not held_at_limit(0, 90, 42, C.HIGH, 1.12, amps, -1.12, 1.14)   # it turns this wheel's way
    assert not held_at_limit(0, 90, 42, C.HIGH, 1.12, amps, 1.12, 1.14)    # no spin: a straight run
    assert not held_at_limit(0, 90, 42, C.HIGH, 1.12, amps, 0.0, -1.14)    # the partner has no setpoint
    assert not held_at_limit(3, 90, 42, C.HIGH, 1.12, amps, -1.12, -1.14)  # this wheel moves
    assert not held_at_limit(0, 90, 42, C.HIGH, 1.12, 512 + 90, -1.12, -1.14)  # 10.99 A


def test_a_held_wheel_pushes_at_full_torque_and_no_harder() -> None:
    """The PID's bounds within 16.5 % either way (duty 42): a motor at duty 42 drawing
    11 A or more its driven way turns at most (42 V / 255 - 11 A R) / (Ke G) rad/s, the
    plant's motor: 0.50 rad/s at 24 V, 0.70 on a full battery's 25.6 V (the sensor's
    bound on a cut encoder's wheel passing for a held one)."""
    assert held_bounds(-100.0, 100.0) == (-C.STALL_HELD_OUTPUT, C.STALL_HELD_OUTPUT)
    assert held_bounds(-5.0, 10.0) == (-5.0, 10.0)                     # a rollback's tighter bound stays
    assert HELD_DUTY == 42
    p = ChairParams()
    ke_g = p.motor_constant * p.gear_ratio

    def fastest(volts: float) -> float:
        return (HELD_DUTY * volts / 255.0 - C.STALL_CURRENT * p.armature_resistance) / ke_g

    assert fastest(24.0) == pytest.approx(0.495, abs=1e-3)
    assert fastest(p.battery_full_voltage) == pytest.approx(0.695, abs=1e-3)


# ---- both backends -------------------------------------------------------------------------
def _push(duration: float, wall: float | None, amps: tuple[float, float], speed: float = 3.0,
          pokes: list[tuple[float, dict[str, float | int]]] | None = None,
          cut: tuple[str, ...] = ("left", "right"), serial: list[tuple[float, bytes]] | None = None,
          ) -> Recording:
    """A neutral command, then rp/lp ``speed`` every 0.1 s; both wheels turning at
    ``speed`` until ``wall`` s, where the encoders of ``cut`` stand (a wall: both; a cut
    encoder: one), the motors drawing ``amps`` (left, right) A from 0.06 s before."""
    command = b"rp%05.2f,lp%05.2f\n" % (speed, speed)
    writes = [(0.02, b"rp0,lp0,\n"), *every(command, 0.2, duration - 0.05), *(serial or [])]
    encoders = {side: turning(duration, side == "left", speed) for side in ("left", "right")}
    currents: list[tuple[float, str, int]] = []
    if wall is not None:
        encoders = {side: stand_still(train, wall, duration) if side in cut else train
                    for side, train in encoders.items()}
        currents = [(wall - 0.06, side, current_millivolts(a)) for side, a in zip(("left", "right"), amps,
                                                                                  strict=True)]
    return recorded(Trace(duration=duration, serial=sorted(writes), encoders=encoders, currents=currents,
                          pokes=pokes or []))


@pytest.mark.simavr
def test_against_a_wall_both_wheels_push_at_their_limit_without_a_fault() -> None:
    """Both encoders stand from 1.0 s, both motors at 12.5 A (the wall): no fault
    (before the senses: DRIVER_DEAD two ticks on), the stall clock runs a tick at a
    time, both wheels at duty 42; the host's commands go on being taken."""
    rec = _push(2.0, 1.0, (12.5, 12.5))
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    pushing = [(t, a) for t, a in tick_states(rec) if t > 1.15]
    assert all(a["faultFlags"] == 0 and a["pwmL"] == a["pwmR"] == HELD_DUTY for _, a in pushing)
    clock = [a["stallTime"] for _, a in pushing]
    assert clock[0] > 0.0 and np.all(np.diff(clock) == pytest.approx(0.05, abs=0.002))


@pytest.mark.simavr
def test_a_spin_about_a_wheel_at_its_limit_is_held_not_a_stalled_encoder() -> None:
    """A spin asked (right +1, left -1 rad/s): from 1.0 s the right encoder stands, its
    motor at 12.5 A and its integral poked at 0.97 s to full torque (it climbed at its
    limit), while the left turns on its own way at 1 rad/s (the chair pivots about the
    right wheel, as a spin on a grade at the chair's limit does): no fault, the right
    wheel held at duty 42 within a second, and from then on the stall clock running a
    tick at a time. Red without the spin's case in the held rule: ``ENC_STALL_R``."""
    duration = 3.0
    writes = [(0.02, b"rp0,lp0,\n"), *every(b"rp01.00,ln01.00\n", 0.2, duration - 0.05)]
    encoders = {"left": turning(duration, True, -1.0),
                "right": stand_still(turning(duration, False, 1.0), 1.0, duration)}
    currents = [(0.94, "left", current_millivolts(-2.0)), (0.94, "right", current_millivolts(12.5))]
    rec = recorded(Trace(duration=duration, serial=sorted(writes), encoders=encoders, currents=currents,
                         pokes=[(0.97, {"integralR": 2.5})]))
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    assert all(a["faultFlags"] == 0 for _, a in ticks)
    held = [(t, a) for t, a in ticks if t > 1.1 and a["pwmR"] == HELD_DUTY]
    assert held and held[0][0] < 2.0
    assert all(a["pwmR"] == HELD_DUTY for t, a in ticks if t > held[0][0])
    clock = [a["stallTime"] for t, a in ticks if t > held[0][0]]
    assert clock[0] > 0.0 and np.all(np.diff(clock) == pytest.approx(0.05, abs=0.002))


@pytest.mark.simavr
def test_the_stall_clock_run_out_stops_the_chair_until_a_stop_then_neutral() -> None:
    """The same wall, the stall clock set at 14.8 s at 1.3 s: 15 s comes four ticks on,
    ``EVT:STALL_TIMEOUT``, not a fault: the chair halted (the emergency flag, both
    targets and setpoints 0 at once: it stands against the wall) and parked under the
    hold, the motors off, its clock back at 0. The host's rp/lp commands are refused
    until it sends a stop (``limit``, then ``neutral``) and a neutral command has stood:
    then it drives again. Red with the timeout's branch taken out: no event, the chair
    pushing on."""
    rec = _push(3.2, 1.0, (12.5, 12.5), pokes=[(1.3, {"stallTime": 14.8})],
                serial=[(2.02, b"rp0,lp0,\n"), *every(b"rp0,lp0,\n", 2.1, 2.4, 0.05)])
    events = board_lines(rec, b"EVT:")
    assert events[:2] == [b"EVT:PARAMS_DEFAULT,blank", b"EVT:STALL_TIMEOUT"], events
    assert board_lines(rec, b"EVT:FAULT") == []
    ticks = tick_states(rec)
    at = next(t for t, a in ticks if a["limitLatched"])
    assert 1.45 < at < 1.6
    assert all(a["faultFlags"] == 0 for _, a in ticks)
    assert all(a["stallTime"] == 0.0 and a["targetL"] == a["targetR"] == 0.0 and a["needNeutral"]
               and a["setpointL"] == a["setpointR"] == 0.0 and a["emergencyStop"] and a["parked"]
               and a["pwmL"] == a["pwmR"] == 0
               for t, a in ticks if at <= t < 2.0)
    assert b"ERR:limit" in rec.tx
    assert any(a["targetL"] > 0.0 for t, a in ticks if t > 2.5)      # driving again after neutral


def _wall_that_gives(duration: float, gives: tuple[float, float], creep: float, mirrored: bool
                     ) -> EdgeTrain:
    """A wheel at 3 rad/s from 0.3 s into a wall at 1.0 s, standing but for ``gives``
    (s, s), where the wall gives and the wheel creeps at ``creep`` rad/s."""
    a, b = gives
    t = np.array([0.0, 0.3, 1.0, a, b, duration])
    angle = np.array([0.0, 0.0, 2.1, 2.1, 2.1 + creep * (b - a), 2.1 + creep * (b - a)])
    return edges_from_trajectory(t, 0.5 + (-1 if mirrored else 1) * angle * COUNTS_PER_RAD)


@pytest.mark.simavr
def test_the_stall_clock_starts_over_when_a_wheel_moves() -> None:
    """Both wheels against a wall from 1.0 s, both motors at 12.5 A; from 1.52 to 1.62 s
    the wall gives and they creep at 0.25 rad/s (20 counts a tick, their motors at 2 A),
    then stand again at 12.5 A: the clock runs a tick at a time while they stand, is 0
    at a tick that counts their creep, and starts over from one tick once they are held
    again; no event, no fault. Red with the clock kept through the creep: it goes on
    from where it was."""
    duration = 2.4
    command = b"rp03.00,lp03.00\n"
    encoders = {side: _wall_that_gives(duration, (1.52, 1.62), 0.25, side == "left")
                for side in ("left", "right")}
    currents = sorted((t, side, current_millivolts(amps)) for side in ("left", "right")
                      for t, amps in ((0.94, 12.5), (1.52, 2.0), (1.62, 12.5)))
    rec = recorded(Trace(duration=duration, serial=[(0.02, b"rp0,lp0,\n"), *every(command, 0.2, 2.35)],
                         encoders=encoders, currents=currents))
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    ticks = tick_states(rec)
    assert all(a["faultFlags"] == 0 for _, a in ticks)
    clock = [(t, a["stallTime"]) for t, a in ticks if t > 1.0]
    moved = [i for i, (t, c) in enumerate(clock) if 1.52 < t < 1.72 and c == 0.0]
    assert moved, clock
    assert clock[moved[0] - 1][1] > 0.4                   # the clock had run since the wall
    after = [c for _, c in clock[moved[-1] + 1:]]
    assert after[0] == pytest.approx(0.05, abs=1e-6)     # starts over
    assert len(after) > 10 and np.all(np.diff(after) == pytest.approx(0.05, abs=0.002))


@pytest.mark.simavr
def test_both_encoders_cut_while_the_motors_spin_is_still_the_driver_fault() -> None:
    """Both encoders cut at 1.0 s while the motors turn on, drawing 3 A (not held: a
    turning motor's back-EMF takes the current off its limit): DRIVER_DEAD two ticks
    on, as before the current senses."""
    rec = _push(1.5, 1.0, (3.0, -3.0))
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,DRIVER_DEAD"]


@pytest.mark.simavr
def test_both_encoders_cut_going_downhill_is_still_the_driver_fault() -> None:
    """Both encoders cut at 1.0 s while the chair, driven forward, is pushed downhill
    faster than its duty turns it: its motors draw 12.5 A braking (against their DIR).
    Not held (a braking current says nothing of a stand): DRIVER_DEAD two ticks on.
    Red with the current's sign ignored: held, no fault, the chair runs on."""
    rec = _push(1.5, 1.0, (-12.5, -12.5))
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,DRIVER_DEAD"]


@pytest.mark.simavr
def test_one_encoder_cut_while_its_partner_turns_is_its_stall_fault_at_any_current() -> None:
    """The right encoder cut at 1.0 s, its motor at 12.5 A, the left wheel turning on at
    3 rad/s: the partner carries the chair, so the right wheel is not held but its
    encoder failed: ENC_STALL_R."""
    rec = _push(1.5, 1.0, (3.0, 12.5), cut=("right",))
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,ENC_STALL_R"]


@pytest.mark.simavr
def test_a_failed_current_sense_latches_its_fault() -> None:
    """The left sense's output cut (0 V on A1) at 0.5 s while the chair drives on the
    level: ``EVT:FAULT,CURRENT_SENSE`` at the tick after the ADC read it; the chair
    stops along the emergency ramp: from that tick the emergency flag, the targets 0,
    each setpoint down by ``estop_decel`` a tick (15 rad/s², 0.75 a tick) to 0, the
    host's commands (on until 0.95 s) refused."""
    writes = [(0.02, b"rp0,lp0,\n"), *every(b"rp03.00,lp03.00\n", 0.2, 0.95)]
    rec = recorded(Trace(duration=1.0, serial=writes,
                         encoders={side: turning(1.0, side == "left", 3.0) for side in ("left", "right")},
                         currents=[(0.5, "left", 0)]))
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,CURRENT_SENSE"]
    ticks = tick_states(rec)
    k = next(i for i, (_, a) in enumerate(ticks) if a["faultFlags"])
    assert 0.5 < ticks[k][0] < 0.62
    step = f32(ticks[k][1]["estopDecel"] * 0.05)
    assert step == pytest.approx(0.75)
    before = ticks[k - 1][1]["setpointL"]
    assert before > step
    for _, a in ticks[k:]:
        assert a["emergencyStop"] and a["targetL"] == a["targetR"] == 0.0
        assert a["setpointL"] == pytest.approx(max(0.0, before - step), abs=1e-6)
        before = a["setpointL"]
    assert before == 0.0
    assert b"ERR:fault" in rec.tx


# ---- the parameter ---------------------------------------------------------------------------
def test_stall_timeout_is_a_parameter_in_range_saved_and_restored() -> None:
    """``stall_timeout``: 15 s by default, 1 to 60 s (``ERR:range`` beyond); a save brings
    it back at boot (the EEPROM block), ``defaults`` restores 15 s."""
    for bad in (b"0.99", b"60.01"):
        fw = Firmware()
        assert fw.feed(b"set:stall_timeout=" + bad + b"\n") == b"ERR:range\r\n"
        assert fw.state.stallTimeout == 15.0
    fw = Firmware()
    assert fw.feed(b"get:stall_timeout\n") == b"PAR:stall_timeout,15.0000\r\n"
    assert fw.feed(b"set:stall_timeout=5\n") == b"PAR:stall_timeout,5.0000\r\n"
    fw.feed(b"save\n")
    while fw.state.eeBusy:
        fw.eeprom_ready()
    again = Firmware(eeprom=fw.state.eeprom)
    assert again.boot_output().endswith(b"EVT:PARAMS_LOADED\r\n") and again.state.stallTimeout == 5.0
    again.feed(b"defaults\n")
    assert again.state.stallTimeout == 15.0


@pytest.mark.simavr
def test_a_shorter_stall_timeout_stops_the_chair_sooner() -> None:
    """``set:stall_timeout=1`` first; both encoders stand from 1.0 s, both motors at
    12.5 A: the clock starts at the first tick that finds them held and runs out 20
    ticks later, ``EVT:STALL_TIMEOUT`` 1.0 to 1.2 s after the wall, no clock set by
    hand. Red with the parameter at 15 s: no event within the trace."""
    rec = _push(2.6, 1.0, (12.5, 12.5), serial=[(0.01, b"set:stall_timeout=1\n")])
    assert board_lines(rec, b"EVT:STALL") == [b"EVT:STALL_TIMEOUT"]
    at = next(t for t, a in tick_states(rec) if a["limitLatched"])
    assert 2.0 < at < 2.2
