"""Motion profiles a random trace may end in (``wcdrive.hil.traces.generate_trace``):
scripted encoder motion that looks to the firmware like the situations its grade and
motor rules judge, since the traces' encoders are not driven by the duty. ``grade``:
both wheels slow far below a steady command (the grade limit, then the hold);
``dead_motor``: one wheel falls back (the motor rule); ``overrun``: one or both wheels
run beyond the setpoint (OVERSPEED, a motor that does not brake, the runaway rule);
``parked_drift``: a parked chair creeps (the hold, ROLLAWAY).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wcdrive.firmware.constants import ACCEL_MAX, CPR, MAX_ACCEL, TWO_PI
from wcdrive.hil.trace_base import FIRST_COMMAND_S, MAX_TRACE_EDGE_RATE, Draw, Trace
from wcdrive.plant.encoders import STATE_OF_PHASE, EdgeTrain, edges_from_trajectory, state_for_count
from wcdrive.protocol.codec import SEQ_MAX, frame

# ---- motion profiles ---------------------------------------------------------
#: The motion profiles a trace may end in (``motion_profile``).
PROFILES = ("grade", "dead_motor", "overrun", "parked_drift")
#: How likely a trace without a storm or a flood ends in a motion profile.
PROFILE_P = 0.4
#: Encoder counts per radian of wheel.
COUNTS_PER_RAD = float(CPR) / float(TWO_PI)
#: Fastest wheel speed a profile scripts (rad/s), well inside MAX_TRACE_EDGE_RATE.
PROFILE_MAX_SPEED = 30.0
#: How long a profile's preamble takes when it starts in mid-trace: the e-stop ramps the
#: setpoints down at the default e-stop rate (at most 17.59 rad/s at 15 rad/s^2), the
#: chair parks, and ``reset`` clears any fault or e-stop.
PREAMBLE_S = 1.3
#: A neutral command this long before the first motion: the board has confirmed it
#: (NEUTRAL_TICKS ticks) by then.
NEUTRAL_LEAD_S = 0.12
#: The least time each profile is given after its preamble (s).
_PROFILE_MIN_S = {"grade": 1.2, "dead_motor": 1.0, "overrun": 1.2, "parked_drift": 0.8}


@dataclass
class _Script:
    """A profile's script: the serial writes (v3 frames when ``framed``, numbered on
    from ``seq``), and each wheel's speed its way (rad/s, forward positive) as points
    joined linearly."""

    framed: bool
    seq: int
    serial: list[tuple[float, bytes]] = field(default_factory=list)
    speeds: dict[str, list[tuple[float, float]]] = field(default_factory=dict)

    def send(self, draw: Draw, t: float, body: bytes) -> None:
        """``body`` at ``t``: a v3 frame when the script frames, else as is (a stop or a
        WHEEL command ends at its comma; any other command gets a line end)."""
        if self.framed:
            self.seq = (self.seq + 1) % (SEQ_MAX + 1)
            line = frame(body, self.seq)
        elif body.endswith(b","):
            line = body + draw.choice([b"", b"\n"])
        else:
            line = body + b"\n"
        self.serial.append((t, line))

    def repeat(self, draw: Draw, start: float, end: float, body: bytes) -> None:
        """``body`` from ``start`` until ``end``, every 50 to 300 ms: within the watchdog."""
        t = start
        while t < end:
            self.send(draw, t, body)
            t += draw.real(0.05, 0.3)


def _wheel(sign: int, right: float, left: float) -> bytes:
    """A WHEEL command for both wheels turning ``sign``'s way (3 decimals)."""
    way = "p" if sign > 0 else "n"
    return f"r{way}{right:.3f},l{way}{left:.3f},".encode()


def motion_profile(draw: Draw, trace: Trace) -> Trace:
    """``trace`` ending in one of ``PROFILES``: from a time drawn on, its serial writes
    and both encoders are a script that leads the firmware onto one of its limit rules.
    The encoders stay open loop, so the script shapes them as the chair would move:

    - ``grade``: both wheels commanded the same, their speed falling to a crawl (3 to 20 %
      of the setpoint) while the PID winds the duty up: both held back alike, the grade
      limit (EVT:STALLED_ON_GRADE), then the hold with the wheels still creeping.
    - ``dead_motor``: both commanded the same, one wheel keeps its setpoint while the
      other falls back to 5 to 60 % of it: effort without progress on one wheel only
      (EVT:FAULT,MOTOR_L/R).
    - ``overrun``: both wheels, or one, speeding up beyond the setpoint while the PID
      brakes: both is gravity on the chair (EVT:OVERSPEED); one gaining slowly while the
      other holds its setpoint is its motor not braking (EVT:FAULT,MOTOR_L/R), gaining
      fast the runaway rule's.
    - ``parked_drift``: a short drive or none, a stop, the chair parked, then one or
      both wheels creeping (20 to 800 counts/s): the hold drives them back, and past
      ``ROLLAWAY_COUNTS`` (2 cm) EVT:ROLLAWAY.

    A profile starts at boot (the trace's earlier writes dropped), or in mid-trace after
    a preamble that brings any state back to a parked chair taking commands
    (``defaults``, ``estop``, ``reset``, a stop; ``PREAMBLE_S``). The commands are v3
    frames when the trace said hello before (or by a draw). Returns a new trace; the
    encoders before the profile are the trace's own."""
    kind = draw.choice(PROFILES)
    duration = trace.duration
    need = _PROFILE_MIN_S[kind]
    latest = duration - need - PREAMBLE_S
    at_boot = not (latest > FIRST_COMMAND_S + 0.2 and draw.boolean(0.6))
    if at_boot:
        t0 = FIRST_COMMAND_S      # the wheels rest until then in every trace
        kept: list[tuple[float, bytes]] = []
    else:
        t0 = draw.real(FIRST_COMMAND_S + 0.2, latest)
        kept = [(t, data) for t, data in trace.serial if t < t0]
    hello = any(b"hello" in data for _, data in kept)
    script = _Script(hello or draw.boolean(0.3), draw.integer(0, SEQ_MAX))
    start = t0 + (draw.real(0.0, 0.03) if at_boot else 0.0)
    if at_boot:                    # after the boot, neutral before motion
        script.send(draw, t0, b"rp0,lp0,")
        start += NEUTRAL_LEAD_S
    else:
        script.send(draw, t0, b"defaults")
        script.send(draw, t0 + 0.005, b"estop")
        script.send(draw, t0 + 0.7, b"reset")
        script.send(draw, t0 + PREAMBLE_S - 0.20, b"reset")
        script.send(draw, t0 + PREAMBLE_S - 0.15, b"rp0,lp0,")      # neutral, confirmed by the start
        start = t0 + PREAMBLE_S
    accel = float(MAX_ACCEL)
    if draw.boolean(0.3):
        accel = draw.real(3.0, float(ACCEL_MAX))
        script.send(draw, start if at_boot else start - 0.02, f"set:max_accel={accel:.3f}".encode())
        start += 0.02 if at_boot else 0.0
    for side in ("left", "right"):
        script.speeds[side] = [(t0, 0.0), (start, 0.0)]
    build = {"grade": _grade, "dead_motor": _dead_motor, "overrun": _overrun,
             "parked_drift": _parked_drift}[kind]
    build(draw, script, start, duration, accel)
    encoders = {side: _spliced(trace.encoders[side], t0, script.speeds[side], duration,
                               -1.0 if side == "left" else 1.0)
                for side in ("left", "right")}
    serial = kept + sorted(script.serial, key=lambda write: write[0])
    return Trace(duration=duration, serial=serial, encoders=encoders,
                 millis_start=trace.millis_start, eeprom=trace.eeprom, profile=kind,
                 profile_start=t0)


def _top_speed(draw: Draw, lo: float, hi: float, room: float, accel: float) -> float:
    """A setpoint in [lo, hi] rad/s, lower when the profile has only ``room`` s after its
    ramp would end at ``lo``: the ramp (``accel``) may take half the time left."""
    return draw.real(lo, max(lo, min(hi, lo + 0.5 * room * accel)))


def _grade(draw: Draw, script: _Script, start: float, end: float, accel: float) -> None:
    """Both wheels held back to a crawl under a steady command (``motion_profile``)."""
    top = _top_speed(draw, 1.5, 8.0, end - start - _PROFILE_MIN_S["grade"], accel)
    sign = draw.choice([1, -1])
    script.repeat(draw, start, end, _wheel(sign, top, top))
    ramp = top / accel
    peak = draw.real(0.5, 1.0) * top
    crawl = max(0.15, draw.real(0.03, 0.2) * top)
    slowing = draw.real(0.2, 1.0)
    last = draw.real(0.5, 0.95)
    for side in ("left", "right"):
        k = 1.0 if side == "right" else 1.0 + draw.real(-0.04, 0.04)
        script.speeds[side] += [(start + ramp, sign * k * peak),
                                (start + ramp + slowing, sign * k * crawl),
                                (max(end, start + ramp + slowing + 0.1), sign * k * crawl * last)]


def _dead_motor(draw: Draw, script: _Script, start: float, end: float, accel: float) -> None:
    """One wheel falls back while the other keeps the setpoint (``motion_profile``)."""
    top = _top_speed(draw, 1.5, 8.0, end - start - _PROFILE_MIN_S["dead_motor"], accel)
    sign = draw.choice([1, -1])
    script.repeat(draw, start, end, _wheel(sign, top, top))
    ramp = top / accel
    dead = draw.choice(["left", "right"])
    fails = start + draw.real(0.3, 1.0) * ramp
    crawl = max(0.2, draw.real(0.05, 0.6) * top)
    slowing = draw.real(0.1, 0.6)
    for side in ("left", "right"):
        if side == dead:
            at_fail = top * (fails - start) / ramp
            script.speeds[side] += [(fails, sign * at_fail),
                                    (fails + slowing, sign * min(at_fail, crawl)),
                                    (max(end, fails + slowing + 0.1), sign * min(at_fail, crawl) * 0.8)]
        else:
            script.speeds[side] += [(start + ramp, sign * top * draw.real(0.96, 1.0)),
                                    (max(end, start + ramp + 0.1), sign * top * draw.real(0.96, 1.0))]


def _overrun(draw: Draw, script: _Script, start: float, end: float, accel: float) -> None:
    """Both wheels, or one, driven on beyond the setpoint (``motion_profile``)."""
    both = draw.boolean(0.5)
    top = _top_speed(draw, 1.5 if both else 3.2, 8.0, end - start - _PROFILE_MIN_S["overrun"], accel)
    sign = draw.choice([1, -1])
    ramp = top / accel
    hold = draw.real(0.0, 0.4)
    gains = start + ramp + hold
    script.repeat(draw, start, end, _wheel(sign, top, top))
    if both:
        # Gravity on the chair: both gain at 1.5 to 6 rad/s^2 (each within 10 % of the
        # other); now and then the host stops meanwhile, and the wheels still gain.
        rate = draw.real(1.5, 6.0)
        if draw.boolean(0.3):
            stop = gains + draw.real(0.0, 0.3)
            script.serial = [(t, data) for t, data in script.serial if t < stop]
            script.repeat(draw, stop, end, b"rp0,lp0,")
        for side in ("left", "right"):
            k = rate * (1.0 + draw.real(-0.1, 0.1))
            fastest = min(PROFILE_MAX_SPEED, top + k * max(0.1, end - gains))
            script.speeds[side] += [(start + ramp, sign * top), (gains, sign * top),
                                    (gains + (fastest - top) / k, sign * fastest)]
        return
    # One wheel: a step of 1.3 to 2 rad/s beyond the setpoint in 0.15 s, then a slow gain
    # (0.6 to 1 rad/s^2: less than the runaway rule's 0.07 rad/s a tick) or, now and
    # then, a fast one (1.6 to 5 rad/s^2).
    runs = draw.choice(["left", "right"])
    step = draw.real(1.3, 2.0)
    rate = draw.real(0.6, 1.0) if draw.boolean(0.75) else draw.real(1.6, 5.0)
    for side in ("left", "right"):
        if side == runs:
            fastest = min(PROFILE_MAX_SPEED, top + step + rate * max(0.1, end - gains))
            script.speeds[side] += [(start + ramp, sign * top), (gains, sign * top),
                                    (gains + 0.15, sign * (top + step)),
                                    (gains + 0.15 + (fastest - top - step) / rate, sign * fastest)]
        else:
            script.speeds[side] += [(start + ramp, sign * top),
                                    (max(end, start + ramp + 0.1), sign * top * draw.real(0.98, 1.0))]


def _parked_drift(draw: Draw, script: _Script, start: float, end: float, accel: float) -> None:
    """A stop, the chair parked, then the wheels creeping (``motion_profile``)."""
    t = start
    if draw.boolean(0.5) and end - start > 1.6:
        top = draw.real(0.5, 3.0)
        sign = draw.choice([1, -1])
        drive = draw.real(0.3, 0.8)
        script.repeat(draw, t, t + drive, _wheel(sign, top, top))
        reached = min(top, accel * drive)
        for side in ("left", "right"):
            script.speeds[side] += [(t + reached / accel, sign * reached), (t + drive, sign * reached),
                                    (t + drive + reached / accel, 0.0)]
        t += drive
        script.send(draw, t, b"rp0,lp0,")
        t += reached / accel
    rest = t + draw.real(0.2, 0.5)
    if draw.boolean(0.5):
        script.repeat(draw, rest, end, b"rp0,lp0,")
    both = draw.boolean(0.7)
    way = draw.choice([1, -1])
    moving = ["left", "right"] if both else [draw.choice(["left", "right"])]
    for side in ("left", "right"):
        script.speeds[side].append((rest, 0.0))
    t = rest
    while t < end:
        creep = draw.real(0.1, 1.2)
        counts_s = draw.real(20.0, 800.0) if draw.boolean(0.8) else 0.0
        for side in moving:
            k = way * counts_s * (1.0 + draw.real(-0.2, 0.2)) / COUNTS_PER_RAD
            script.speeds[side] += [(t + 0.05, k), (t + creep, k)]
        t += creep
    for side in ("left", "right"):
        script.speeds[side].append((max(t, end), script.speeds[side][-1][1]))


#: The phase (count % 4) of each AB state: ``STATE_OF_PHASE`` inverted.
_PHASE_OF_STATE = np.array([STATE_OF_PHASE.index(state) for state in range(4)], dtype=np.int64)


def _count_at(train: EdgeTrain, t: float) -> int:
    """The count a quadrature decoder shows at ``t``: legal steps counted from
    ``start_count``, illegal ones (both pins at once) not."""
    states = np.concatenate((np.array([state_for_count(train.start_count)], dtype=np.int64),
                             train.states[train.times < t].astype(np.int64)))
    steps = np.diff(_PHASE_OF_STATE[states]) % 4
    return train.start_count + int(np.sum(steps == 1)) - int(np.sum(steps == 3))


def _spliced(train: EdgeTrain, t0: float, speeds: list[tuple[float, float]], end: float,
             counting: float) -> EdgeTrain:
    """``train``'s edges before ``t0``, then a wheel turning at ``speeds`` (rad/s its
    way, linear between the points; ``counting``: +1 where the counts rise forward, -1 on
    the mirrored left) until ``end``, from the count ``train`` shows at ``t0``."""
    times = np.arange(t0, end + 0.005, 0.005)
    points = np.array(sorted(speeds))
    rate = np.interp(times, points[:, 0], points[:, 1]) * COUNTS_PER_RAD * counting
    rate = np.clip(rate, -MAX_TRACE_EDGE_RATE, MAX_TRACE_EDGE_RATE)
    travel = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(times))))
    tail = edges_from_trajectory(times, _count_at(train, t0) + 0.5 + travel)
    keep = train.times < t0
    return EdgeTrain(np.concatenate((train.times[keep], tail.times)),
                     np.concatenate((train.states[keep], tail.states.astype(train.states.dtype))),
                     train.start_count, tail.end_count)
