"""Fault-detection behaviours that the other suites let a mutant break unseen (a mutation
check of ``checkWheel``/``noEffect``/``emergencyHalt``/the storm guard): each test is
red on the mutant it names and green on the firmware as it is.

Like tests/firmware/test_fault_detection.py, every trace runs on the compiled firmware in simavr
and is replayed on the port in lock step (``wcdrive.hil.lockstep``, 0 mismatches), the
encoders open loop: they do what the test says, whatever the motors do.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wcdrive.avr.timer0 import OVERFLOW_CYCLES, TIMER0_START_CYCLE, storm_window
from wcdrive.boards.simavr.virtual_mega import F_CPU
from wcdrive.firmware import constants as C
from wcdrive.firmware.quadrature import QuadratureDecoder
from wcdrive.hil.lockstep import Event, Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory

pytestmark = pytest.mark.simavr

COUNTS_PER_RAD = 10000 / (2 * math.pi)
HIGH = 1
#: Every driven trace opens as a host does after a boot: a neutral command at 10 ms, which
#: has stood NEUTRAL_TICKS ticks by LEAD (protocol/PROTOCOL.md, "Neutral before motion").
#: The times the tests give (commands, the wheels' motion, the trace's length) count from
#: LEAD: whole control ticks (4), so the ticks fall about where they did before the rule.
#: (Not 3: the motor check's reference restarts on any rise of the dragged wheel's
#: measured speed, the encoder's quantisation jitter included, so whether MOTOR_L
#: latches within its 1.5 s depends on the ticks' millisecond phase against the edges:
#: with 0.15 s it had not latched by 2.5 s.)
LEAD = 0.2
NEUTRAL = (0.01, b"rp0,lp0,\n")


def _trace(duration: float, serial: list[tuple[float, bytes]], encoders: dict[str, EdgeTrain]) -> Trace:
    """A trace of ``duration`` s from LEAD on, after the neutral command: ``serial``'s
    times from LEAD (``encoders`` from ``_track``, already so)."""
    return Trace(duration=duration + LEAD, serial=[NEUTRAL, *((round(t + LEAD, 4), d) for t, d in serial)],
                 encoders=encoders)


def _track(points: list[tuple[float, float]], mirrored: bool = False) -> EdgeTrain:
    """The edges of a wheel whose angle (rad) moves linearly between ``(t, angle)``
    points, times from LEAD (still before it; the left wheel is mounted mirrored: its
    counts run backwards)."""
    points = [(0.0, points[0][1]), *((t + LEAD, a) for t, a in points)]
    sign = -1 if mirrored else 1
    times = np.array([t for t, _ in points])
    counts = np.array([0.5 + sign * a * COUNTS_PER_RAD for _, a in points])
    return edges_from_trajectory(times, counts)


def _steady(rad_s: float, t0: float, t1: float, mirrored: bool = False) -> EdgeTrain:
    return _track([(0.0, 0.0), (t0, 0.0), (t1, rad_s * (t1 - t0))], mirrored)


def _commands(command: bytes, t0: float, t1: float, period: float = 0.1) -> list[tuple[float, bytes]]:
    return [(float(t), command) for t in np.arange(t0, t1, period)]


def _run(trace: Trace) -> Recording:
    recording = record(trace)
    report = compare(recording)
    assert report.mismatches == [], "\n".join(str(m) for m in report.mismatches[:10])
    return recording


def _events(tx: bytes) -> list[bytes]:
    """The EVT lines, but the boot's EVT:PARAMS_* (the EEPROM parameters)."""
    lines = tx.split(b"\r\n")
    return [line for line in lines if line.startswith(b"EVT:") and not line.startswith(b"EVT:PARAMS")]


def _ticks(recording: Recording) -> list[tuple[dict, dict, Event]]:
    """Each tick as (the state before it, the state after it, the event)."""
    out = []
    before = recording.initial
    for ev in recording.events:
        if ev.kind == "tick":
            out.append((before, ev.after, ev))
        before = ev.after
    return out


def _stall_oracle(recording: Recording, side: str) -> tuple[list[int], int | None]:
    """PROTOCOL.md "Faults" applied to the recording: per tick, how many ticks in a row
    the wheel was driven (duty >= FAULT_STALL_PWM in the direction of a non-zero setpoint,
    as the previous tick left them) without a count; and the index of the first tick at
    which that reaches FAULT_STALL_TICKS (None: never)."""
    runs, run, due = [], 0, None
    for i, (before, after, _) in enumerate(_ticks(recording)):
        setpoint = before["setpoint" + side]
        driven = (before["pwm" + side] >= C.FAULT_STALL_PWM and setpoint != 0.0
                  and (before["dir" + side] == HIGH) == (setpoint > 0.0))
        run = run + 1 if driven and after["encTick" + side] == before["encTick" + side] else 0
        runs.append(run)
        if due is None and run >= C.FAULT_STALL_TICKS:
            due = i
    return runs, due


def _first_fault(recording: Recording) -> int | None:
    for i, (_, after, _) in enumerate(_ticks(recording)):
        if after["faultFlags"]:
            return i
    return None


# -- the stall check: when it counts, and that it trips on the exact tick ------------------

def test_a_stall_latches_on_the_exact_tick_the_protocol_says() -> None:
    """Left encoder cut at 0.40 s under drive: the fault latches at the tick where the
    wheel has been driven without a count for FAULT_STALL_TICKS ticks in a row, not one
    tick later (kills ``>`` for ``>=``)."""
    trace = _trace(1.0, _commands(b"rp3.0,lp3.0,", 0.02, 1.0),
                   encoders={"left": _steady(3.0, 0.02, 0.40, mirrored=True),
                             "right": _steady(3.0, 0.02, 1.0)})
    recording = _run(trace)
    runs, due = _stall_oracle(recording, "L")
    assert due is not None, runs
    assert _first_fault(recording) == due, runs
    assert _ticks(recording)[due][1]["faultFlags"] == 0x01
    assert _events(recording.tx) == [b"EVT:FAULT,ENC_STALL_L"]


def _brake_then_lock_trace() -> Trace:
    """Both wheels at their 3 rad/s setpoint; from 1.0 s the left one is pushed to 6 rad/s
    (downhill), so the PID brakes it hard (duty against the setpoint); just before the tick
    at 1.301 s (from LEAD) it locks until 1.43 s (the two ticks after that one see no count, the duty
    still against the setpoint as the first of them starts), then rolls on at 3 rad/s."""
    lock, roll = 1.3005, 1.43
    at_lock = 2.94 + 6 * (lock - 1.0)
    left = _track([(0.0, 0.0), (0.02, 0.0), (1.0, 2.94), (lock, at_lock), (roll, at_lock),
                   (1.8, at_lock + 3 * (1.8 - roll))], mirrored=True)
    return _trace(1.8, _commands(b"rp3.0,lp3.0,", 0.02, 1.8),
                  encoders={"left": left, "right": _steady(3.0, 0.02, 1.8)})


def test_a_wheel_braked_without_a_count_is_not_a_stall() -> None:
    """A duty against a non-zero setpoint (braking) without a count is not a stall: only
    ticks driven toward the setpoint count (kills the stall check without its direction
    or setpoint condition). The lock lasts two ticks; fewer than FAULT_STALL_TICKS of them
    were driven toward the setpoint, so nothing latches."""
    recording = _run(_brake_then_lock_trace())
    ticks = _ticks(recording)
    # The scenario is the one described: two ticks without a count, braking as they start.
    still = [i for i, (b, a, _) in enumerate(ticks) if i > 5 and a["encTickL"] == b["encTickL"]]
    assert len(still) == 2 and still[1] == still[0] + 1, still
    assert ticks[still[0]][0]["dirL"] != HIGH and ticks[still[0]][0]["pwmL"] >= C.FAULT_STALL_PWM
    runs, due = _stall_oracle(recording, "L")
    assert due is None and max(runs) == 1, runs
    assert _events(recording.tx) == [] and _first_fault(recording) is None


# -- the hold rule ------------------------------------------------------------------------

def _assert_held(recording: Recording, side: str, suspect: list[int]) -> None:
    ticks = _ticks(recording)
    assert suspect
    for i in suspect:
        before, after, _ = ticks[i]
        for name in ("output", "integral", "prevMeas", "pwm", "dir"):
            assert after[name + side] == before[name + side], (i, name, before[name + side],
                                                               after[name + side])


def test_a_suspect_tick_holds_the_wheels_output() -> None:
    """A tick in which a wheel is driven without a count, or measures against its
    setpoint, holds that wheel's PID output, integral and duty (kills the PID running on
    a suspect wheel): after the left encoder is cut, and while the right one counts
    backwards."""
    cut = _trace(1.0, _commands(b"rp3.0,lp3.0,", 0.02, 1.0),
                 encoders={"left": _steady(3.0, 0.02, 0.40, mirrored=True),
                           "right": _steady(3.0, 0.02, 1.0)})
    recording = _run(cut)
    suspect = [i for i, (_, a, _) in enumerate(_ticks(recording))
               if 0 < a["stallTicksL"] < C.FAULT_STALL_TICKS and not a["faultFlags"]]
    _assert_held(recording, "L", suspect)

    swapped = _trace(1.2, _commands(b"rp3.0,lp3.0,", 0.02, 1.2),
                     encoders={"left": _steady(3.0, 0.02, 1.2, mirrored=True),
                               "right": _steady(-3.0, 0.02, 1.2)})
    recording = _run(swapped)
    suspect = [i for i, (_, a, _) in enumerate(_ticks(recording))
               if 0 < a["reverseTicksR"] < C.FAULT_REVERSE_TICKS and not a["faultFlags"]]
    assert len(suspect) == C.FAULT_REVERSE_TICKS - 1
    _assert_held(recording, "R", suspect)


# -- the motor (no-effect) check ------------------------------------------------------------

def test_effort_without_progress_latches_a_motor_fault() -> None:
    """The left wheel is only dragged along at 0.5 rad/s toward a steady 3 rad/s
    setpoint: its duty climbs FAULT_EFFORT_PWM above its lowest and stays there for
    FAULT_EFFORT_TICKS ticks with no gain in speed: MOTOR_L, the left motor off and the
    right one, still turning, braked (kills ``noEffect`` never tripping)."""
    trace = _trace(2.0, _commands(b"rp3.0,lp3.0,", 0.02, 2.0),     # MOTOR_L at 1.7 s
                   encoders={"left": _steady(0.5, 0.02, 2.0, mirrored=True),
                             "right": _steady(3.0, 0.02, 2.0)})
    recording = _run(trace)
    assert _events(recording.tx) == [b"EVT:FAULT,MOTOR_L"]
    ticks = _ticks(recording)
    at = _first_fault(recording)
    assert at is not None and ticks[at][1]["faultFlags"] == 0x80
    # Not before the setpoint was steady (3 rad/s after 0.6 s) plus FAULT_EFFORT_TICKS.
    steady = next(i for i, (_, a, _) in enumerate(ticks) if a["setpointL"] == 3.0)
    assert at >= steady + C.FAULT_EFFORT_TICKS
    duties = [b["pwmL"] for b, _, _ in ticks[at - C.FAULT_EFFORT_TICKS + 1:at + 1]]
    assert min(duties) >= ticks[at][1]["effortPwmL"] + C.FAULT_EFFORT_PWM, duties
    last = recording.events[-1]
    assert last.pwm[0] == 0 and last.after["dirR"] == C.LOW and last.after["brakeReleased"] == 0


# -- emergencyHalt: the integrators start from zero ----------------------------------------

def test_an_estop_brakes_from_a_zeroed_integrator() -> None:
    """Both wheels lag their 3 rad/s setpoint (the integrators wind up positive), then
    reach 2.8 rad/s and hold it; an e-stop at 1.02 s: at the first tick after it the
    integrators restart from zero, so the PID brakes at once (DIR reversed) instead of
    pushing on with what kept the chair rolling (kills ``emergencyHalt`` keeping them)."""
    def wheel(mirrored: bool) -> EdgeTrain:
        t = np.linspace(0.0, 1.0, 41)
        points = [(float(x), 1.4 * float(x) ** 2) for x in t] + [(1.6, 1.4 + 2.8 * 0.6)]
        return _track(points, mirrored)

    serial = [*_commands(b"rp3.0,lp3.0,", 0.02, 1.0), (1.02, b"estop\n")]
    recording = _run(_trace(1.3, serial,
                            encoders={"left": wheel(True), "right": wheel(False)}))
    assert _events(recording.tx) == [b"EVT:ESTOP"]
    ticks = _ticks(recording)
    first = next(i for i, (_, a, _) in enumerate(ticks) if a["estopLatched"])
    before, after = ticks[first - 1][1], ticks[first][1]     # the ticks around the estop
    for side in "LR":
        assert before["integral" + side] > 0.5                     # wound up
        assert -0.1 < after["integral" + side] <= 0.0, after["integral" + side]
        assert after["dir" + side] != HIGH and after["output" + side] < 0.0
        assert after["parked"] == 0                               # braking under closed loop


# -- the storm guard: the port's ISR model masks at the firmware's edge ---------------------

def test_the_port_decoder_masks_at_the_same_edge_as_the_firmware() -> None:
    """STORM_EDGES - 1 edges in each of two Timer0 windows are all counted (the window
    count clears); the STORM_EDGES-th edge in a third masks the encoder. The port's ISR
    model (``QuadratureDecoder``, edge by edge and in bulk) stops at the very edge the
    firmware's ISR stops at: the same count, storm set (kills a decoder that never
    masks, or whose window never clears). The edges keep 4,300 cycles clear of where
    ``storm_window`` starts each window (the ELF's windows start ~3,700 cycles later:
    test_storm_windows_start_where_the_port_says)."""
    first = int(storm_window(round(0.2 * F_CPU))) + 1
    start = TIMER0_START_CYCLE + 128 * 64       # the cycle window 0 starts at, per the port
    per_window = [C.STORM_EDGES - 1, C.STORM_EDGES - 1, C.STORM_EDGES + 4]
    cycles = np.concatenate([start + (first + w) * OVERFLOW_CYCLES + 4300 + 140 * np.arange(n)
                             for w, n in enumerate(per_window)])
    forward = np.array([0b01, 0b00, 0b10, 0b11])      # counting up from 11
    states = forward[np.arange(cycles.size) % 4]
    train = EdgeTrain(cycles / F_CPU, states, 0, int(cycles.size))
    assert [int(np.sum(storm_window(cycles) == first + w)) for w in range(3)] == per_window

    recording = _run(Trace(duration=0.35, encoders={"left": train}))
    assert _events(recording.tx) == [b"EVT:FAULT,ENC_IMPLAUSIBLE_L"]
    masked_at = 2 * (C.STORM_EDGES - 1) + C.STORM_EDGES
    assert recording.events[-1].after["encTickL"] == masked_at

    one = QuadratureDecoder()
    for state, cycle in zip(states.tolist(), cycles.tolist(), strict=True):
        one.edge(state, int(storm_window(cycle)))
    bulk = QuadratureDecoder()
    bulk.edges_in_windows(states, storm_window(cycles))
    for decoder in (one, bulk):
        assert decoder.storm and decoder.count == masked_at and decoder.illegal == 0


def test_storm_windows_start_where_the_port_says(mega) -> None:
    """The port's Timer0 grid (``FIRST_OVERFLOW_CYCLE``, ``TIMER0_START_CYCLE``, on which
    ``storm_window`` rests) is the ELF's: its first overflow is counted within 40 cycles
    of FIRST_OVERFLOW_CYCLE (a start-up that grows by a few globals moves it more: a
    tolerance of 200 once let it drift 189 cycles unseen)."""
    from wcdrive.boards.port_loop import FIRST_OVERFLOW_CYCLE

    mega.run_for((FIRST_OVERFLOW_CYCLE - 40) / F_CPU)
    assert mega.read("timer0_overflow_count") == 0
    mega.run_for(80 / F_CPU)
    assert mega.read("timer0_overflow_count") == 1
