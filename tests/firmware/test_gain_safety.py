"""Safe parameters: every combination of runtime parameters the board
accepts tracks a velocity step on the plant without sustained oscillation, and without
tripping a fault on the healthy plant.

The accepted space is read from ``wcdrive.firmware.params.PARAMS`` (the spec's
``[[parameter]]`` table and ranges, as the firmware holds them), so the tests follow
``protocol/spec.toml``: they fail while the spec accepts gains that oscillate, and pass
once its ranges are tightened. benchmarks/gain_scan.py gives the figures (a grid of
kp x ki x kd, random points of any box of ranges).

The step, as a user drives it (``step_response``), on the port at the Mega's timing
(``PortLoop``) with the pymunk chair (``Plant``):

* ``hello``, then ``set:`` for every parameter given, each a v3 frame that must be
  ACKed, 25 ms apart (at most two answers a tick, under ``ERR_LINES_PER_TICK``);
* a neutral CMDVEL frame ``x:0.000,t:0.000`` every ``COMMAND_PERIOD`` for
  ``NEUTRAL_FRAMES`` periods before the step (the board drives only once a neutral
  command has stood ``NEUTRAL_TICKS`` ticks: protocol/PROTOCOL.md, "Neutral before
  motion"; streamed, as a host forwarding cmd_vel does, so no watchdog fires before it);
* from ``STEP_AT``, a CMDVEL frame ``x:<v>,t:0`` every ``COMMAND_PERIOD`` (40 ms, less
  than a control period, so no ``watchdog_ms`` the board accepts can fire);
* the run lasts until ``WINDOW_S`` after both wheels have settled (below).

The property, on each wheel, from the TRUE wheel speed ``w`` (``plant.left.speed``,
``plant.right.speed``) sampled every ``SAMPLE_S``:

* ``w*``, the final setpoint: the firmware's wheel target (``targetL``/``targetR``, that
  is ``v / r`` capped by ``max_wheel``), taken when the ramp reaches it;
* settled: the ramp (``setpointL``/``setpointR``) has reached both targets, and the
  wheel has come within ``SETTLE_BAND * |w*| + THRESHOLD`` of its target, or
  ``RISE_MAX_S`` has passed since the ramp arrived, if it never comes that close (so a
  limit cycle that never reaches the target is still watched). Waiting for the wheel
  keeps the rise out of the window: at ``max_accel`` 7 rad/s^2 the ramp arrives
  before the wheel, whose acceleration the driver's current limit bounds, and the
  casters swinging round at the start of a reverse jolt the wheels;
* a reversal is a turn of ``w`` by at least ``THRESHOLD`` (a zigzag filter: after
  the first move of ``THRESHOLD`` sets the direction, a reversal is counted each time
  ``w`` retreats ``THRESHOLD`` from its latest extreme). ``THRESHOLD`` is 0.1 rad/s
  (15 mm/s at the rim): 8 encoder counts a 50 ms tick, far above the one-count
  quantisation (0.0126 rad/s) the PID reacts to, and a sixth of the swing of the gains
  of the reported oscillation (0.6 rad/s peak to peak). Turns of the speed are counted rather than
  crossings of ``w*``, because a loop can chatter without ever reaching its target:
  with the oscillating gains at 2 m/s the duty swings from 255 to -55 every other tick
  while the wheel stays 1.6 rad/s below its setpoint;
* no sustained oscillation: at most ``MAX_REVERSALS`` (2: one overshoot and its
  return) on each wheel within ``WINDOW_S`` (3 s) of settling, before any stop;
* no fault: ``faultFlags`` (when the state has the field) stays 0, and the board sends
  no ``EVT:`` line (fault, watchdog), no ``ERR:``/``NAK:``, and never stops. This is
  asked of wheels tuned alike (the same three gains on both). Wheels tuned far apart
  (one at kp 1, ki 0.01, the other strong) do not drive straight: the weak one lags,
  the chair turns, and the weak wheel can be dragged against its setpoint until the
  reversed-encoder or motor check stops the chair. That stop is the safety net doing
  its job; that the accepted ranges allow such a pair is an open problem (a rule on the
  difference between the wheels' gains, not a range).

Hypothesis draws every parameter over its whole accepted range (the ends drawn often),
left and right apart, and the step over 0.3 to 2.0 m/s, forward or reverse. The
oscillation and the faults are two tests over the same draws, so a failure names its
cause; explicit cases cover the corners of the box and the oscillating gains, and
``test_the_check_can_fail`` shows that the check rejects the reported oscillation
whatever the spec accepts.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wcdrive.avr.f32 import f32
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.params import PARAMS, Param
from wcdrive.plant import Plant
from wcdrive.plant.params import ChairParams
from wcdrive.protocol.codec import encode_cmdvel, encode_set, frame

#: rad/s: how far the wheel speed must move back from an extreme to count a reversal.
THRESHOLD = 0.1
#: Reversals allowed per wheel in the window.
MAX_REVERSALS = 2
#: s watched once a wheel has settled.
WINDOW_S = 3.0
#: A wheel has settled once the ramp has reached the target and the wheel has come
#: within this fraction of it (plus THRESHOLD) ...
SETTLE_BAND = 0.1
#: ... or this long after the ramp reached it, if it never comes that close.
RISE_MAX_S = 3.0
#: s between samples of the true wheel speeds.
SAMPLE_S = 0.002
#: s: the step's first command (later when many set: frames go first).
STEP_AT = 0.4
#: s between the host's CMDVEL frames.
COMMAND_PERIOD = 0.04
#: s between the set: frames.
SET_PERIOD = 0.025
#: Neutral frames before the step, COMMAND_PERIOD apart: the first has stood
#: NEUTRAL_TICKS (2) ticks of 50 ms by the step, wherever between ticks it came.
NEUTRAL_FRAMES = 3
#: m/s: the magnitudes of the step.
SPEED_MIN, SPEED_MAX = 0.3, 2.0
#: m/s: the steps of the explicit cases.
CORNER_SPEEDS = (0.3, 2.0, -1.0, -2.0)

BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}
GAINS = ("kp_l", "ki_l", "kd_l", "kp_r", "ki_r", "kd_r")
#: The reported oscillation: "with kp=100, ki=100, kd=10 ... the wheels oscillate".
OSCILLATING_GAINS = {"kp_l": 100.0, "ki_l": 100.0, "kd_l": 10.0, "kp_r": 100.0, "ki_r": 100.0, "kd_r": 10.0}


def wire_value(p: Param, value: float) -> str:
    """The value as the host sends it: whole milliseconds for ``watchdog_ms``, else four
    decimals, kept inside the accepted range."""
    if p.integer:
        return str(int(value))
    low = math.ceil(p.low * 10_000 - 1e-6) / 10_000
    high = math.floor(p.high * 10_000 + 1e-6) / 10_000
    return f"{min(max(round(value, 4), low), high):.4f}"


@dataclass
class StepRun:
    """One step on the plant: what was set, what the wheels did, what the board said."""

    values: dict[str, str]          # parameter -> the text sent
    speed: float                    # m/s commanded
    target: tuple[float, float]     # rad/s: w*, left and right (0, 0 if never ramped)
    ramped_s: float | None          # when the ramp reached both targets
    settled_s: tuple[float | None, float | None]   # when each wheel came near its target
    halted_s: float | None          # when a fault or an emergency stop began
    reversals: tuple[int, int]      # per wheel, in its window
    peak_error: tuple[float, float]   # max |w - w*| in the window, rad/s
    final_error: tuple[float, float]  # mean w - w* over the window's last 0.5 s
    yaw: float                      # rad: the largest |heading| reached
    fault: int                      # faultFlags (0 when the state has no such field)
    bad_lines: list[str] = field(default_factory=list)   # EVT:, ERR:, NAK: lines
    unacked: list[str] = field(default_factory=list)     # set: frames not ACKed

    @property
    def worst(self) -> int:
        return max(self.reversals)

    def oscillation(self) -> list[str]:
        """Why the run breaks the oscillation half of the property (empty: it holds)."""
        out = []
        if self.ramped_s is None and self.halted_s is None:
            out.append("the ramp never reached the target")
        if self.worst > MAX_REVERSALS:
            out.append(f"{self.reversals} reversals (left, right) > {MAX_REVERSALS}")
        return out

    def faults(self) -> list[str]:
        """Why the run breaks the no-fault half of the property (empty: it holds)."""
        out = []
        if self.fault:
            out.append(f"fault latched: faultFlags={self.fault:#x}")
        if self.halted_s is not None:
            out.append(f"stopped at {self.halted_s:.2f} s")
        if self.bad_lines:
            out.append(f"lines: {self.bad_lines[:4]}")
        return out

    def failures(self) -> list[str]:
        return self.oscillation() + self.faults()

    def describe(self) -> str:
        sets = ", ".join(f"{k}={v}" for k, v in self.values.items())
        return (f"{sets}; step {self.speed:+.3f} m/s, w* {self.target[0]:.3f} rad/s; "
                f"reversals {self.reversals}, peak |e| {self.peak_error[0]:.3f}/"
                f"{self.peak_error[1]:.3f} rad/s, final e {self.final_error[0]:+.3f}/"
                f"{self.final_error[1]:+.3f}, yaw {math.degrees(self.yaw):.0f} deg: "
                f"{'; '.join(self.failures()) or 'ok'}")


def count_reversals(speed: np.ndarray, threshold: float = THRESHOLD) -> int:
    """The turns of ``speed`` by at least ``threshold`` (a zigzag filter): the first move
    of ``threshold`` sets the direction; then each retreat of ``threshold`` from the
    latest extreme is a reversal."""
    if speed.size == 0:
        return 0
    high = low = float(speed[0])
    direction = 0
    count = 0
    for value in speed.tolist():
        if direction == 0:
            high, low = max(high, value), min(low, value)
            if value >= low + threshold:
                direction, high = 1, value
            elif value <= high - threshold:
                direction, low = -1, value
        elif direction > 0:
            if value > high:
                high = value
            elif value <= high - threshold:
                count, direction, low = count + 1, -1, value
        elif value < low:
            low = value
        elif value >= low + threshold:
            count, direction, high = count + 1, 1, value
    return count


def step_response(values: dict[str, float], speed: float, *, window_s: float = WINDOW_S,
                  threshold: float = THRESHOLD, firmware: Firmware | None = None) -> StepRun:
    """Sets ``values`` (parameter name -> value; the others keep their defaults) as a
    host does, steps to ``speed`` m/s and keeps commanding it until ``window_s`` after
    both wheels have settled (module docstring). ``firmware``: a board in a given state
    instead of one just out of reset."""
    plant = Plant()
    loop = PortLoop(plant, firmware=firmware)
    s = loop.fw.state
    seq = 0

    def send(command: bytes, at: float) -> int:
        nonlocal seq
        seq = seq % 65535 + 1
        loop.send(frame(command, seq), at=round(at * F_CPU))
        return seq

    t = 0.01
    send(b"hello", t)
    sent: dict[str, str] = {}
    set_seqs: dict[int, str] = {}
    for name, value in values.items():
        t += SET_PERIOD
        sent[name] = wire_value(BY_NAME[name], value)
        set_seqs[send(f"set:{name}={sent[name]}".encode(), t)] = name
    step_at = max(STEP_AT, t + SET_PERIOD + NEUTRAL_FRAMES * COMMAND_PERIOD)
    command = encode_cmdvel(speed, 0.0)
    for k in range(NEUTRAL_FRAMES, 0, -1):     # the host's neutral first, then the step
        send(encode_cmdvel(0.0, 0.0), step_at - k * COMMAND_PERIOD)

    rows: list[tuple[float, float, float]] = []
    next_command = step_at
    chunk = round(SAMPLE_S * F_CPU)
    cycle = 0
    ramped: float | None = None
    halted: float | None = None
    target = (0.0, 0.0)
    settled: list[float | None] = [None, None]
    yaw = 0.0
    # the slowest ramp there can be (the top speed at the lowest max_accel), a rise, a window
    end = step_at + float(BY_NAME["max_wheel"].high) / float(BY_NAME["max_accel"].low)
    end += RISE_MAX_S + window_s
    while cycle < end * F_CPU:
        horizon = (cycle + chunk) / F_CPU
        while next_command <= horizon:
            send(command, next_command)
            next_command += COMMAND_PERIOD
        cycle += chunk
        loop.run_until(cycle)
        now = cycle / F_CPU
        yaw = max(yaw, abs(plant.pose[2]))
        if getattr(s, "faultFlags", 0) or s.emergencyStop or s.estopLatched:
            halted = now
            break
        if ramped is None:
            if not (now > step_at and s.targetL != 0.0 and s.setpointL == s.targetL
                    and s.setpointR == s.targetR):
                continue
            ramped, target = now, (s.targetL, s.targetR)
        speeds = (plant.left.speed, plant.right.speed)
        rows.append((now, *speeds))
        for i in range(2):
            if settled[i] is None and (abs(speeds[i] - target[i])
                                       <= SETTLE_BAND * abs(target[i]) + threshold):
                settled[i] = now
        end = max(ramped + RISE_MAX_S if ts is None else ts for ts in settled) + window_s

    text = b"".join(out for _, out in loop.take_output()).decode("ascii", "replace")
    lines = text.split("\r\n")
    acked = {int(line[4:]) for line in lines if line.startswith("ACK:")}
    reversals, peak, final = [0, 0], [math.nan, math.nan], [math.nan, math.nan]
    if ramped is not None and rows:
        data = np.array(rows)
        for i in range(2):
            start = settled[i]
            if start is None:
                start = ramped + RISE_MAX_S
            window = data[(data[:, 0] >= start) & (data[:, 0] <= start + window_s)]
            if len(window):
                err = window[:, 1 + i] - target[i]
                reversals[i] = count_reversals(window[:, 1 + i], threshold)
                peak[i] = float(np.max(np.abs(err)))
                final[i] = float(np.mean(err[window[:, 0] >= window[-1, 0] - 0.5]))
    return StepRun(values=sent, speed=speed, target=target, ramped_s=ramped,
                   settled_s=(settled[0], settled[1]), halted_s=halted,
                   reversals=(reversals[0], reversals[1]), peak_error=(peak[0], peak[1]),
                   final_error=(final[0], final[1]), yaw=yaw,
                   fault=int(getattr(s, "faultFlags", 0)),
                   bad_lines=[line for line in lines if line.startswith(("EVT:", "ERR:", "NAK:"))
                              and not line.startswith("EVT:PARAMS")],   # the boot's EEPROM event
                   unacked=[name for q, name in set_seqs.items() if q not in acked])


def run_step(values: dict[str, float], speed: float) -> StepRun:
    """``step_response``, checking that the board took every value (they are meant to be
    inside its ranges)."""
    run = step_response(values, speed)
    assert not run.unacked, f"the board refused set: {run.unacked} ({run.values})"
    return run


def matched(values: dict[str, float]) -> bool:
    """Both wheels have the same three gains."""
    return all(values.get(f"{g}_l") == values.get(f"{g}_r") for g in ("kp", "ki", "kd"))


def check(values: dict[str, float], speed: float) -> StepRun:
    """The whole property: no sustained oscillation, and for wheels tuned alike no fault."""
    run = run_step(values, speed)
    if matched(values):
        assert not run.failures(), run.describe()
    else:
        assert not run.oscillation(), run.describe()
    return run


# --- the accepted space ---------------------------------------------------------------

def _values(p: Param) -> st.SearchStrategy[float]:
    """A parameter over its whole accepted range, its ends drawn often."""
    if p.integer:
        return st.integers(int(p.low), int(p.high)).map(float)
    return st.one_of(st.sampled_from([float(p.low), float(p.high)]),
                     st.floats(float(p.low), float(p.high), allow_nan=False))


#: Every parameter but ``brake_fitted``, which says what the chair has (this plant has no
#: brake, whose driver would see an open coil: tests/firmware/test_brake.py).
#: The drive limits cap the step itself (its speed, its ramp: docs/safety.md, "Drive
#: limits"), so a step under them never reaches what was asked; they are held to their
#: own figures in tests/firmware/test_drive_limits.py and stay at their defaults here, and
#: so does the drive profile that sets them (profile 0, whose limits are those defaults).
DRIVE_LIMITS = ("fwd_speed", "rev_speed", "drive_accel", "drive_decel", "turn_speed", "turn_accel",
                "turn_at_speed", "tremor_damping", "profile")
PARAMETER_SETS = st.fixed_dictionaries({p.name: _values(p) for p in PARAMS
                                        if p.name != "brake_fitted" and p.name not in DRIVE_LIMITS})
SPEEDS = st.builds(lambda magnitude, sign: sign * round(magnitude, 3),
                   st.floats(SPEED_MIN, SPEED_MAX), st.sampled_from([1.0, -1.0]))


def _end(name: str, high: bool) -> float:
    p = BY_NAME[name]
    return float(p.high if high else p.low)


def gain_corners() -> list[dict[str, float]]:
    """Every corner of the (kp, ki, kd) box, both wheels alike, the rest at the defaults."""
    out = []
    for ends in itertools.product((False, True), repeat=3):
        gains = {g: _end(f"{g}_l", high) for g, high in zip(("kp", "ki", "kd"), ends, strict=True)}
        out.append({f"{g}_{side}": v for side in "lr" for g, v in gains.items()})
    return out


def other_corners() -> list[dict[str, float]]:
    """The strongest gains with each end of the other parameters, and the two wheels at
    opposite corners of the gain box."""
    strong = {name: _end(name, True) for name in GAINS}
    out = [{**strong, name: _end(name, high)}
           for name in ("max_wheel", "max_accel", "estop_decel", "watchdog_ms")
           for high in (False, True)]
    out.append({f"{g}_{side}": _end(f"{g}_{side}", side == "l") for side in "lr" for g in ("kp", "ki", "kd")})
    return out


def accepted(values: dict[str, float]) -> dict[str, float]:
    """``values`` clipped to the ranges of PARAMS (the nearest values the board accepts)."""
    return {k: min(max(v, _end(k, False)), _end(k, True)) for k, v in values.items()}


def _id(values: dict[str, float]) -> str:
    return ",".join(f"{k}={v:g}" for k, v in values.items())


# --- the tests ------------------------------------------------------------------------

def test_count_reversals() -> None:
    assert count_reversals(np.array([0.0, 1.0, 2.0, 3.0, 2.95, 3.0])) == 0     # a rise and dither
    assert count_reversals(np.array([0.0, 3.0, 3.3, 3.1, 3.0, 3.05])) == 1     # one overshoot
    assert count_reversals(np.array([0.0, 3.3, 2.9, 3.1, 3.05])) == 2         # and its return
    assert count_reversals(np.array([3.0, 3.2, 3.0] * 5)) == 9
    assert count_reversals(np.array([-3.0, -3.2, -3.0, -3.2])) == 2           # the sign is no matter
    assert count_reversals(np.array([1.0, 1.05, 1.0, 1.09, 1.0])) == 0        # under THRESHOLD
    assert count_reversals(np.array([])) == 0


def test_the_defaults_track_a_step() -> None:
    for speed in (SPEED_MIN, 1.0, -1.0, SPEED_MAX, -SPEED_MAX):
        run = check({}, speed)
        assert abs(run.final_error[0]) < 0.5 and abs(run.final_error[1]) < 0.5, run.describe()


def test_the_check_can_fail() -> None:
    """The oscillating gains break the property at every speed, and the reversal count
    alone catches their oscillation (a fault may stop the chatter first at some speeds).
    The gains are written into the firmware's globals, so this holds whatever ranges the
    spec accepts."""
    runs = []
    for speed in (SPEED_MIN, 1.0, -1.0, SPEED_MAX):
        board = Firmware(boot_millis=0)
        for name, value in OSCILLATING_GAINS.items():
            setattr(board.state, BY_NAME[name].field, f32(value))
        runs.append(step_response({}, speed, firmware=board))
        assert runs[-1].failures(), runs[-1].describe()
    assert max(run.worst for run in runs) > MAX_REVERSALS, [run.describe() for run in runs]


@pytest.mark.parametrize("speed", CORNER_SPEEDS)
def test_the_accepted_gains_nearest_the_oscillating_ones(speed: float) -> None:
    """kp=100, ki=100, kd=10, or the nearest gains the board accepts."""
    check(accepted(OSCILLATING_GAINS), speed)


@pytest.mark.parametrize("speed", CORNER_SPEEDS)
@pytest.mark.parametrize("values", gain_corners() + other_corners(), ids=_id)
def test_the_corners_of_the_accepted_box(values: dict[str, float], speed: float) -> None:
    check(values, speed)


EXAMPLES = max(40, 2 * settings().max_examples)


@settings(parent=settings(), max_examples=EXAMPLES)
@given(values=PARAMETER_SETS, speed=SPEEDS)
@example(values=accepted(OSCILLATING_GAINS), speed=1.0)
def test_no_accepted_combination_oscillates(values: dict[str, float], speed: float) -> None:
    run = run_step(values, speed)
    assert not run.oscillation(), run.describe()


#: The fastest setpoint ramp the chair can follow (rad/s^2 at the wheel): its hardest
#: change of speed at the driver's current limit (``ChairParams.max_braking``, 1.12
#: m/s^2, over the wheel's radius: 7.37). The board accepts ``max_accel`` up to
#: ``ACCEL_MAX`` (7), within it (``test_a_ramp_faster_than_the_chair_can_follow_is_refused``).
FOLLOWABLE_ACCEL = ChairParams().max_braking / ChairParams().wheel_radius

MATCHED_SETS = PARAMETER_SETS.map(
    lambda v: {**v, **{f"{g}_r": v[f"{g}_l"] for g in ("kp", "ki", "kd")},
               "max_accel": min(v["max_accel"], float(f32(FOLLOWABLE_ACCEL)))})


@settings(parent=settings(), max_examples=EXAMPLES)
@given(values=MATCHED_SETS, speed=SPEEDS)
def test_no_accepted_combination_with_wheels_tuned_alike_trips_a_fault(values: dict[str, float],
                                                                       speed: float) -> None:
    """Over every accepted combination with a ramp the chair can follow."""
    run = run_step(values, speed)
    assert not run.faults(), run.describe()


def test_a_ramp_faster_than_the_chair_can_follow_is_refused() -> None:
    """ACCEL_MAX is within what the chair can follow; at 20 rad/s^2 (accepted once) kp 1,
    ki 10, kd 0 and a -2.0 m/s step latched MOTOR_R on a healthy chair. Now 20 is refused,
    and the same step at ACCEL_MAX latches nothing."""
    assert C.ACCEL_MAX <= FOLLOWABLE_ACCEL
    with pytest.raises(ValueError):
        encode_set("max_accel", 20.0)
    values = {**accepted({"kp_l": 1.0, "ki_l": 10.0, "kd_l": 0.0, "kp_r": 1.0, "ki_r": 10.0,
                          "kd_r": 0.0}), "max_accel": float(C.ACCEL_MAX)}
    run = run_step(values, -2.0)
    assert not run.faults(), run.describe()
