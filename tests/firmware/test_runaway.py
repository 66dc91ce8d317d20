"""A reversed encoder whose reading flips while its wheel's setpoint crosses zero must
not run away. The chair rolls at 0.5 m/s and is told to turn on the spot at 1.5 s; at
2.0 s the encoder of the wheel whose setpoint reverses gets its A and B swapped, while
that setpoint still ramps down from forward. The measured speed flips sign with the
setpoint, so setpoint and measurement agree in sign and the "against" rule
(FAULT_REVERSE_TICKS) never counts: the PID pushed the wheel forward to cut a backward
speed it read, the wheel sped up, the encoder read it as faster backward, and the duty
wound up to 255 with no fault (the right wheel at 11.1 rad/s after 6 s, 1.7 m/s).

What tells it from a healthy wheel is ``runsAway``: braked (duty FAULT_RUNAWAY_PWM or
more against its measured motion), FAULT_REVERSE_SPEED or more beyond its setpoint that
way, and FAULT_RUNAWAY_GAIN or more faster than the speed the PID last ran on, for
FAULT_RUNAWAY_TICKS ticks in a row. The ground truth here is the plant's: the faulty
wheel's true speed and the chair's travel after the fault.

The pushes at the end are the other side of it: a wheel pushed faster than its setpoint
while the PID brakes it looks the same to the firmware, and the tests there show where
the line is (open loop on simavr, the port in lock step, as in
tests/firmware/test_fault_detection.py).
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import thorough
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware import constants as C
from wcdrive.firmware.control import runs_away
from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.plant.faults import Fault
from wcdrive.protocol.codec import encode_cmdvel
from wcdrive.sim import runner
from wcdrive.sim.scenario import MOTION_START_S, Scenario, load

#: The scenario's host sends a neutral command first and its segments from
#: MOTION_START_S (20 ms before "Neutral before motion"): the fault comes as long after
#: them as it did, 0.5 s into the turn.
#: s the host's motion starts after its neutral command in the runs built here (3 control
#: ticks: the neutral has stood NEUTRAL_TICKS ticks, and the tick phase is as it was).
NEUTRAL_LEAD_S = 0.15
FAULT_AT = round(2.0 + MOTION_START_S - 0.02, 3)
#: (the side whose encoder is reversed, the turn's t:) - the wheel whose setpoint reverses.
CASES = [("right", -1.0), ("left", 1.0), ("left", 3.0), ("right", -3.0)]
#: Bounds after the fault, from the plant: latched within this many s of it...
LATCH_WITHIN_S = 0.4
#: ...the faulty wheel never faster than this (rad/s; it turned at 2.0 to 2.4 when the
#: encoder flipped, 3.28 at the 0.5 m/s cruise; before the fix it reached 9.5 to 11.1)...
PEAK_WHEEL_RAD_S = 3.6
#: ...and the chair travels at most this far (m) from the fault on (0.22 to 0.45).
TRAVEL_M = 0.5


def _scenario(tmp_path: Path, side: str, w: float) -> Scenario:
    path = tmp_path / f"runaway_{side}_{w}.toml"
    path.write_text(f'name = "runaway"\nhost_rate_hz = 10\nsettle_s = 0.0\n'
                    f"[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 1.5\n"
                    f"[[segment]]\ncmdvel = [0.0, {w}]\nduration = 3.5\n"
                    f'[[fault]]\nat = {FAULT_AT}\nkind = "encoder_reversed"\nside = "{side}"\n')
    return load(str(path))


@cache
def _run(directory: str, side: str, w: float, backend: str) -> runner.SimResult:
    return runner.run(_scenario(Path(directory), side, w), backend=backend)


def _check_bounds(r: runner.SimResult, side: str) -> None:
    event = f"EVT:FAULT,ENC_REVERSED_{side[0].upper()}"
    faults = [(t, line) for t, line in r.link.events if line.startswith("EVT:FAULT")]
    assert faults and faults[0][1] == event, r.link.events
    assert faults[0][0] - FAULT_AT <= LATCH_WITHIN_S, faults
    wheel = 0 if side == "left" else 1
    after = r.board.tick_time >= FAULT_AT
    peak = float(np.max(np.abs(r.truth.wheel_speed[after, wheel])))
    assert peak <= PEAK_WHEEL_RAD_S, peak
    m = r.fault_metrics()
    assert m["travel_after_fault_m"] is not None and m["travel_after_fault_m"] <= TRAVEL_M, m
    assert m["standstill_after_fault_s"] is not None, m          # it stops, and stays stopped
    assert r.board.pwm[-1].tolist() == [0, 0]


@pytest.mark.parametrize(("side", "w"), CASES)
def test_a_reversed_encoder_flipping_with_its_setpoint_is_caught_on_the_port(
        tmp_path_factory, side: str, w: float) -> None:
    r = _run(str(tmp_path_factory.getbasetemp()), side, w, "port")
    _check_bounds(r, side)


#: The firmware's share of CASES at the fast depth (2 s each on simavr): each side once,
#: at each turn rate once; the thorough depth runs all four.
FIRMWARE_CASES = CASES if thorough() else [("right", -1.0), ("left", 3.0)]


@pytest.mark.simavr
@pytest.mark.parametrize(("side", "w"), FIRMWARE_CASES)
def test_a_reversed_encoder_flipping_with_its_setpoint_is_caught_on_the_firmware(
        tmp_path_factory, side: str, w: float) -> None:
    r = _run(str(tmp_path_factory.getbasetemp()), side, w, "simavr")
    assert r.firmware_differences == 0
    _check_bounds(r, side)


def test_runs_away_needs_every_condition() -> None:
    """Braked at FAULT_RUNAWAY_PWM against the measured motion, FAULT_REVERSE_SPEED beyond
    the setpoint that way, FAULT_RUNAWAY_GAIN faster than the PID last saw: each one
    missing (just under its threshold) and it is not a runaway; either sign."""
    pwm, gain, speed = C.FAULT_RUNAWAY_PWM, C.FAULT_RUNAWAY_GAIN, C.FAULT_REVERSE_SPEED
    # The reproduction's tick: setpoint -0.22, measured -2.22 after -2.07, duty 78 forward.
    assert runs_away(78, C.HIGH, -0.22, -2.22, -2.07)
    assert runs_away(pwm, C.HIGH, -0.22, -2.22, -2.22 + gain)
    assert runs_away(pwm, C.LOW, 0.22, 2.22, 2.22 - gain)                   # mirrored
    assert not runs_away(pwm - 1, C.HIGH, -0.22, -2.22, -2.07)              # duty too low
    assert not runs_away(78, C.LOW, -0.22, -2.22, -2.07)                    # driven that way
    assert not runs_away(78, C.HIGH, -0.22, -2.22, -2.22 + 0.5 * gain)      # not speeding up
    assert not runs_away(78, C.HIGH, -0.22, -2.22, -2.5)                    # slowing
    assert not runs_away(78, C.HIGH, -1.5, -2.22, -2.07)                    # < 1 rad/s beyond
    assert runs_away(78, C.HIGH, -2.22 + speed, -2.22, -2.07)               # just 1 beyond
    assert not runs_away(78, C.HIGH, 0.0, -0.9, -0.7)                       # slower than 1
    assert runs_away(78, C.HIGH, 0.5, -1.5, -1.3)                           # opposite signs


# -- the neighbourhood: every moment of the reversal, and healthy manoeuvres ---------------

def _reversed_during_a_turn(v: float, w: float, side: str,
                            fault_at: float) -> tuple[float | None, float, float]:
    """A neutral command, then ``v`` m/s, at 1.5 s a turn on the spot at ``w`` (the host's
    times NEUTRAL_LEAD_S later); ``side``'s encoder reversed at ``fault_at``: (the first
    fault's time after the fault or None, how much faster than at the fault the faulty
    wheel ever turned (rad/s), the travel from the fault (m))."""
    plant = Plant(ChairParams())
    loop = PortLoop(plant, Gyro(ChairParams(), 0), faults=[Fault("encoder_reversed", fault_at, side)])
    loop.send(encode_cmdvel(0.0, 0.0), at=round(0.01 * F_CPU))     # the host's neutral first
    for k in range(60):
        t = 0.05 + 0.1 * k
        loop.send(encode_cmdvel(v, 0.0) if t < 1.5 else encode_cmdvel(0.0, w),
                  at=round((t + NEUTRAL_LEAD_S) * F_CPU))
    wheel = plant.left if side == "left" else plant.right
    seen: dict[str, float] = {}

    def on_tick(now: float) -> None:
        if now >= fault_at:
            seen.setdefault("speed", abs(wheel.speed))
            seen.setdefault("x", plant.pose[0])
            seen.setdefault("y", plant.pose[1])
            seen["peak"] = max(seen.get("peak", 0.0), abs(wheel.speed))
        if loop.fw.state.faultFlags and "latch" not in seen:
            seen["latch"] = now - fault_at

    loop.run_until(round((6 + NEUTRAL_LEAD_S) * F_CPU), on_tick)
    travel = math.hypot(plant.pose[0] - seen["x"], plant.pose[1] - seen["y"])
    return seen.get("latch"), seen["peak"] - seen["speed"], travel


def test_a_reversed_encoder_is_caught_whenever_it_flips_during_a_turn() -> None:
    """0.3 to 1.6 m/s, a turn on the spot at t:+-1 or +-3 at 1.5 s, either encoder
    reversed at any moment from 1.6 to 2.6 s (each time NEUTRAL_LEAD_S later, after the
    host's neutral command; every 50 ms: before, while and after its
    wheel's setpoint crosses zero): 840 runs on the port, every one latches a fault, the
    faulty wheel never 2.5 rad/s faster than when its encoder flipped, the chair travels
    at most 1.2 m after it (before the runaway rule: 47 never latched in 6 s, one wheel
    reached 11.8 rad/s, one chair went 3.4 m). The two worst (0.8 m/s, ``t:+1``, the
    left encoder flipped at 2.70 and 2.75 s, as its setpoint crossed zero: 1.88 and
    2.22 rad/s, 0.62 and 1.08 m, ``ENC_REVERSED_L`` 1.35 and 2.85 s on) came with the
    port's Timer0 grid set to the ELF's (211 cycles later): the flipped reading then
    matched the setpoint at once, and a wheel that reads its setpoint while braked, and
    speeds up 0.25 rad/s^2, is what a healthy wheel held down a grade looks like; the
    rest of the grid stays within 1.25 rad/s and 0.81 m (docs/safety.md). With the grid
    1,221 cycles later again (the supply sense's and the drive limits' globals) the worst
    is the mirror case, the right encoder at 2.75 s with ``t:-1``: 2.19 rad/s, 1.13 m
    (measured with the full grid); with the drive profiles (the grid 420 cycles earlier,
    setup() a ms longer) 2.44 rad/s and 1.12 m. The fast depth
    runs every fourth of the 840 (each speed, turn, side and moment still in, the moment
    turning with the case: 210 runs), the thorough depth all of them."""
    worst_gain = worst_travel = 0.0
    missed = []
    runs = list(itertools.product((0.3, 0.5, 0.8, 1.2, 1.6), (-1.0, 1.0, -3.0, 3.0), ("left", "right"),
                                  range(21)))
    if not thorough():
        runs = runs[::4]       # 21 moments a case: the next case starts one moment later
    for v, w, side, k in runs:
        fault_at = round(1.6 + NEUTRAL_LEAD_S + 0.05 * k, 2)
        latch, gain, travel = _reversed_during_a_turn(v, w, side, fault_at)
        if latch is None:
            missed.append((v, w, side, fault_at))
        worst_gain, worst_travel = max(worst_gain, gain), max(worst_travel, travel)
    print(f"faster than at the fault by at most {worst_gain:.2f} rad/s, travel at most {worst_travel:.2f} m")
    assert missed == []
    assert worst_gain <= 2.5 and worst_travel <= 1.2


#: The grid of healthy manoeuvres (docs/safety.md): forward for 3 s, then a turn
#: on the spot, a reverse, a wheel-for-wheel spin or a curve, at four max_accel.
def _grid() -> list[str]:
    out = []
    for accel in (None, 2.0, 6.0, 7.0):
        params = "" if accel is None else f"[params]\nmax_accel = {accel}\n"
        for v in (0.3, 0.5, 0.8, 1.0, 1.5, 2.0, 2.5):
            second = [f"cmdvel = [0.0, {w}]" for w in (-0.6, -1.5, -3.0, 3.0, 6.0)] + [
                f"cmdvel = [{-v}, 0.0]", f"wheel = [-{v / 0.1524:.2f}, {v / 0.1524:.2f}]",
                f"cmdvel = [{-v}, 1.0]", f"cmdvel = [{v / 2}, -2.0]"]
            out += [f'name = "g"\nhost_rate_hz = 10\nsettle_s = 1.0\n{params}[[segment]]\n'
                    f"cmdvel = [{v}, 0.0]\nduration = 3.0\n[[segment]]\n{seg}\nduration = 2.0\n"
                    for seg in second]
    return out


def test_no_healthy_manoeuvre_of_the_grid_counts_a_runaway_to_its_limit(tmp_path: Path) -> None:
    """The 252 healthy manoeuvres: the runaway count never passes 2 of its
    FAULT_RUNAWAY_TICKS, so it latches none of them. The "against" rule latches 5, spins
    on the spot after a straight run (ENC_REVERSED, each wheel driven against its reading
    at full duty): 6 while Timer0's first overflow was at 30,989 cycles, before the stall
    rule's spin test moved it to 31,115 (the same 5 without the rule's new exemption of a
    wheel driven the way it reads); 5 while it was at 27,917 cycles, before the TX ring's
    512 bytes more moved it to 30,989; 6 until it
    moved to 27,917 cycles with stall_timeout's globals; 7 before the host's neutral
    command moved its motion from 20 ms to MOTION_START_S, 170 ms (the wheel-for-wheel
    spin after 1.5 m/s at max_accel 6 no longer latches ENC_REVERSED_R, which it still
    does from 140 or 220 ms); 8 before the motor rule's bar went to 95 % and Timer0
    started 204 cycles later; 19 at max_accel 5, 2, 10 and 20 before both wheels at their
    limit became EVT:STALLED_ON_GRADE and ACCEL_MAX became 7: docs/safety.md."""
    path = tmp_path / "g.toml"
    grid = _grid()
    assert len(grid) == 252
    longest = latched = 0
    for text in grid:
        path.write_text(text)
        scenario = load(str(path))
        loop = PortLoop(Plant(scenario.params()), Gyro(scenario.params(), 0))
        for t, data in scenario.host_commands():
            if t < scenario.duration:
                loop.send(data, at=round(t * F_CPU))
        runs = [0]

        def on_tick(_: float, loop: PortLoop = loop, runs: list[int] = runs) -> None:
            s = loop.fw.state
            runs[0] = max(runs[0], s.runawayTicksL, s.runawayTicksR)

        loop.run_until(round(scenario.duration * F_CPU), on_tick)
        longest = max(longest, runs[0])
        latched += bool(loop.fw.state.faultFlags)
    print(f"runaway ticks at most {longest}/{C.FAULT_RUNAWAY_TICKS}; {latched} of 252 latched")
    assert longest <= C.FAULT_RUNAWAY_TICKS - 3
    assert latched == 5


# -- pushes: a braked wheel that speeds up because something pushes it -------------------

COUNTS_PER_RAD = 10000 / (2 * math.pi)


def _track(points: list[tuple[float, float]], mirrored: bool = False) -> EdgeTrain:
    """Edges of a wheel whose speed (rad/s) moves linearly between ``(t, speed)`` points
    (the left wheel is mounted mirrored: its counts run backwards)."""
    t = np.linspace(points[0][0], points[-1][0], 2000)
    speed = np.interp(t, [p[0] for p in points], [p[1] for p in points])
    angle = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))))
    sign = -1 if mirrored else 1
    return edges_from_trajectory(t, 0.5 + sign * angle * COUNTS_PER_RAD)


def _push(rate: float, seconds: float) -> Recording:
    """After a neutral command (at 10 ms), both wheels driven slowly (1 rad/s, 0.15 m/s)
    from ``NEUTRAL_LEAD_S`` later; from 1.0 s after that the left one is pushed faster
    at ``rate`` rad/s^2 for ``seconds``, then held at that speed: the PID brakes it (duty
    against the setpoint and the motion) all the while."""
    lead = NEUTRAL_LEAD_S
    end = 2.5 + lead
    top = 1.0 + rate * seconds
    left = _track([(0.0, 0.0), (lead + 0.02, 0.0), (lead + 0.25, 1.0), (lead + 1.0, 1.0),
                   (lead + 1.0 + seconds, top), (end, top)], mirrored=True)
    right = _track([(0.0, 0.0), (lead + 0.02, 0.0), (lead + 0.25, 1.0), (end, 1.0)])
    serial = [(0.01, b"rp0,lp0,\n")]
    serial += [(round(float(t), 4), b"rp1.0,lp1.0,") for t in np.arange(lead + 0.02, end, 0.1)]
    recording = record(Trace(duration=end, serial=serial, encoders={"left": left, "right": right}))
    report = compare(recording)
    assert report.mismatches == [], "\n".join(str(m) for m in report.mismatches[:10])
    return recording


def _faults(recording: Recording) -> list[bytes]:
    return [line for line in recording.tx.split(b"\r\n") if line.startswith(b"EVT:FAULT")]


def _braked_while_speeding_up(recording: Recording) -> int:
    """The most ticks in a row the left wheel was braked at FAULT_RUNAWAY_PWM or more
    while its measured speed rose (what the push does)."""
    run = longest = 0
    before = recording.initial
    for ev in recording.events:
        if ev.kind == "tick":
            a = ev.after
            braked = before["pwmL"] >= C.FAULT_RUNAWAY_PWM and before["dirL"] != C.HIGH
            rising = a["filtVelL"] > before["filtVelL"] > 0.0
            run = run + 1 if braked and rising else 0
            longest = max(longest, run)
        before = ev.after
    return longest


@pytest.mark.simavr
def test_pushing_a_slowly_driven_chair_latches_no_fault() -> None:
    """Pushes that speed the braked wheel up, then hold it there: from 1 to 4 rad/s at
    1.2 rad/s^2 (under FAULT_RUNAWAY_GAIN a tick), from 1 to 2.5 rad/s at 3 rad/s^2 (the
    PID brakes at FAULT_RUNAWAY_PWM only once the wheel is ~1.4 rad/s over its setpoint,
    as the push ends), and a shove to 4 rad/s at 30 rad/s^2 (0.1 s): no fault, although
    the PID brakes the wheel while it speeds up."""
    for rate, seconds in ((1.2, 3.0 / 1.2), (3.0, 0.5), (30.0, 0.1)):
        recording = _push(rate, seconds)
        assert _braked_while_speeding_up(recording) >= 2
        assert _faults(recording) == [], (rate, seconds)
        assert max(ev.after["runawayTicksL"] for ev in recording.events) < C.FAULT_RUNAWAY_TICKS


@pytest.mark.simavr
def test_a_push_that_beats_the_brake_for_long_enough_latches() -> None:
    """Where the line is: a push that speeds the braked wheel from 1 to 4 rad/s at
    3 rad/s^2 (0.15 rad/s a tick, over FAULT_RUNAWAY_GAIN) is what a runaway looks like
    to the firmware: ENC_REVERSED_L, and the chair stops. (In the plant, a braking duty of 10 %
    against 1.2 rad/s or more is already at the driver's current limit: this push
    overcomes the motor's hardest brake.)"""
    recording = _push(3.0, 1.0)
    assert _faults(recording) == [b"EVT:FAULT,ENC_REVERSED_L"]


def test_a_ten_percent_brake_from_1_1_rad_s_is_at_the_current_limit() -> None:
    """The plant's driver limits the current when the volts across the armature exceed
    ``i_max_r`` (the limit times its resistance): FAULT_RUNAWAY_PWM against a wheel that
    turns at 1.2 rad/s is past it, so a push that speeds such a wheel up beats the
    motor's hardest brake."""
    plant = Plant(ChairParams())
    s = plant.s
    volts = ChairParams().supply_voltage * C.FAULT_RUNAWAY_PWM / 255.0
    assert volts + s.ke_g * 1.2 > s.i_max_r
