"""Input traces for the firmware: serial bytes and encoder edges on a timeline.

``generate_trace(draw, duration)`` builds a random trace from any source of choices
(``RandomDraw`` for ``wcdrive verify``, ``HypothesisDraw`` for the
property tests, which then shrink), so both use one generator. Traces cover every
command kind, malformed and newline-less commands, awkward decimal strings,
reversals that start pivots and commands that interrupt them, silences past the
watchdog, PPM loss, long saturations, illegal encoder transitions, encoder speeds up
to 60,000 edges/s and boots with ``millis()`` just below its 2**32 wrap; and protocol
v3: frames with sequence numbers and good, bad or missing CRCs (one or more flipped
bits, lower-case hex, no sequence number, the ``$`` flipped to ``,``), hello (which
turns the TLM lines on and from then on refuses unframed lines, but for stops and
estop), get/set of every parameter in and out of range (and, in a quarter of the traces,
``feedback_form`` 1 from the start: the feedback lines' ros2_control tail), estop and reset;
the inhibit inputs pulled low and let go (a third of the traces: glitches under the
debounce, and inputs held 0.1 to 1.5 s; in half of those the brake's manual release too,
push mode); ``brake_fitted`` 1 from the start (a third of the
traces: the brake engaged at rest, released under the hold), and in half of those the
brake driver's status pulled low (coil faults); a motor hot from a long climb (a quarter:
the windings' estimates set below, at and past the thermal rollback, and at the
cut-off, ``Trace.pokes``); the battery's voltage at the supply sense changed a few
times (a third: from a cut wire's 0 V to 29 V, mostly across the low-battery and
cut-off thresholds, ``Trace.supply``); the motors' current senses changed a few times
(a third: mostly about the stall current either way, some small, some a failed sense's
volts, ``Trace.currents``; with the stall clock set near its timeout now and then, so
that the stall timeout can fire within a trace); bursts of
20 to 150 commands back to back (the output budget is spent), floods of long ``set:``
frames at top speed (``flood``: loop() falls behind, received bytes are lost and
accounted for) and encoder storms of 60,000 to 500,000 edges/s (the storm guard, the
implausible-encoder fault). The encoders are scripted, not driven by the duty, so the
rules that read the duty against the wheels' speeds (the grade limit, a dead motor, an
overspeed, the hill hold) get motion profiles that look like them: a trace may end in
one (``wcdrive.hil.profiles``).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable

import numpy as np

from wcdrive.boards.supply_sense import pin_millivolts
from wcdrive.firmware.params import PARAMS
from wcdrive.hil.current_traces import held_against_a_wall
from wcdrive.hil.profiles import PROFILE_P, motion_profile
from wcdrive.hil.trace_base import (  # Draw, RandomDraw, HypothesisDraw, Trace: callers import them here
    FIRST_COMMAND_S,
    MAX_TRACE_EDGE_RATE,
    Draw,
    HypothesisDraw,
    RandomDraw,
    Trace,
    spaced,
)
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory, state_for_count
from wcdrive.protocol.codec import SEQ_MAX, crc16, frame

#: One trace in this many sets ``feedback_form`` 1 first.
FEEDBACK_FORM_EVERY = 4
#: One trace in this many pulls the inhibit inputs low and lets them go (``inhibit_changes``).
INHIBIT_EVERY = 3
#: Three traces in four start as a well-behaved host does after a boot: a neutral command
#: first, the drawn writes NEUTRAL_LEAD_S later (once the board confirmed neutral); the
#: fourth drives from its first write, and its motion is refused until a neutral command
#: comes (chosen by the CRC of the writes, not drawn: every seed draws what it drew before).
NEUTRAL_FIRST_EVERY = 4
NEUTRAL_LEAD_S = 0.12
#: The parameters ``param_command`` draws from: all but ``brake_fitted`` and
#: ``stall_timeout``, so that a seed draws what it drew before they came (``brake_fitted``
#: is set, out of range and in, at the start of the traces that fit the brake;
#: ``stall_timeout`` in the traces with a stand against a wall, ``current_traces``).
DRAWN_PARAMS = tuple(p for p in PARAMS if p.name not in ("brake_fitted", "stall_timeout"))
#: One trace in this many sets ``brake_fitted`` 1 first; half of those pull the brake
#: driver's status low now and then (``pin_pulls``).
BRAKE_FITTED_EVERY = 3
#: One trace in this many sets the windings' estimates hot at some point (``hot_windings``).
HOT_EVERY = 4
#: One trace in this many changes the battery's voltage at the supply sense (``supply_changes``).
SUPPLY_EVERY = 3
#: The least time between two supply changes (s): more than a tick takes, so that a tick
#: reads the voltage before a change or after it.
SUPPLY_SPACING_S = 0.03
#: One trace in this many changes the motors' current senses (``held_against_a_wall``).
CURRENTS_EVERY = 3

__all__ = ["FIRST_COMMAND_S", "MAX_TRACE_EDGE_RATE", "Draw", "HypothesisDraw", "RandomDraw", "Trace",
           "generate_trace"]


# ---- decimal strings -------------------------------------------------------------
def _digits(draw: Draw, lo: int, hi: int) -> str:
    return "".join(str(draw.integer(0, 9)) for _ in range(draw.integer(lo, hi)))


def decimal_text(draw: Draw, magnitude: float, signed: bool) -> str:
    """A decimal string near ``[0, magnitude]``: plain, many digits, exponents, or
    the strings avr-libc rounds differently from correct rounding."""
    kind = draw.integer(0, 7)
    if kind == 0:
        text = f"{draw.real(0.0, magnitude):.3f}"          # the seed host's format
    elif kind == 1:
        text = f"{draw.real(0.0, magnitude):.{draw.integer(0, 9)}f}"
    elif kind == 2:
        text = f"{draw.integer(0, int(magnitude))}.{_digits(draw, 8, 30)}"   # many digits
    elif kind == 3:
        text = draw.choice(["3.14159", "2.68", "7.0000005", "1.00000005960464477539",
                            "0.1", "0.3", "1e0", "2.5e-1", "1.0e-40", "0.0", "00000.5",
                            "1.", ".5", "17.59", "2.68", "9.4", "0.000000000000000000001"])
    elif kind == 4:
        mantissa = draw.real(0.0, 9.99)
        exponent = draw.integer(-45, 1)
        text = f"{mantissa:.{draw.integer(0, 6)}f}e{exponent}"
    elif kind == 5:
        text = "0." + "0" * draw.integer(0, 12) + _digits(draw, 1, 12)
    elif kind == 6:
        text = _digits(draw, 1, 12) + "." + _digits(draw, 0, 12)           # often out of range
    else:
        text = str(draw.real(0.0, magnitude))                              # repr: may have e-05
    if signed and draw.boolean(0.5):
        text = "-" + text
    elif signed and draw.boolean(0.1):
        text = "+" + text
    return text


# ---- commands --------------------------------------------------------------------
def wheel_command(draw: Draw, right: str | None = None, left: str | None = None) -> bytes:
    """A WHEEL command; the speeds' texts are drawn unless given."""
    r = right if right is not None else decimal_text(draw, 17.59, False)
    lv = left if left is not None else decimal_text(draw, 17.59, False)
    return f"r{draw.choice('pn')}{r},l{draw.choice('pn')}{lv},".encode()


def cmdvel_command(draw: Draw, x: float | None = None) -> bytes:
    """A CMDVEL command; ``x`` fixes the linear speed (printed with 3 decimals)."""
    xs = f"{x:.3f}" if x is not None else decimal_text(draw, 2.68, True)
    return f"x:{xs},t:{decimal_text(draw, 2.0, True)},".encode()


def ppm_command(draw: Draw, lost: bool = False) -> bytes:
    """A PPM frame; with ``lost`` one channel is outside the valid range."""
    channels = [draw.integer(1000, 2000) if draw.boolean(0.7) else 1500 for _ in range(8)]
    if lost:
        channels[draw.integer(0, 7)] = draw.choice([0, 899, 2101, 9999, 850])
    return ("ppm:" + ",".join(str(c) for c in channels) + ",").encode()


def malformed_command(draw: Draw) -> bytes:
    """A command the firmware must reject (or, empty lines, ignore)."""
    kind = draw.integer(0, 13)
    if kind == 0:
        return bytes(draw.integer(0, 255) for _ in range(draw.integer(1, 12))) + b"\n"
    if kind == 1:
        return b"x:0.5\n"                                   # missing field
    if kind == 2:
        return b"x:0.5,y:1.0,t:0.1,"                        # extra field in the middle
    if kind == 3:
        return draw.choice([b"x:nan,t:0.1,", b"x:inf,t:0.0,", b"rpnan,lp1.0,", b"x:-inf,t:0,",
                            b"rpinf,lp1,", b"x:0.1,t:NaN,", b"x:INFINITY,t:1,"])
    if kind == 4:
        return draw.choice([b"rp18.0,lp1.0,", b"x:2.69,t:0.0,", b"x:0.0,t:9.5,", b"rp1e3,lp0,",
                            b"x:1e39,t:0,", b"rp99999999999,lp1,"])
    if kind == 5:
        return b"x:0." + b"1" * draw.integer(60, 90) + b",t:0.1,"   # overlong
    if kind == 6:
        return draw.choice([b"rp-1.0,lp1.0,", b"rp 1.0,lp1.0,", b"r1.0,l1.0,", b"rp1.0,rp1.0,",
                            b"rp,lp1,", b"rp1.0x,lp1,", b"x:,t:1,", b"x:1.0.0,t:0,"])
    if kind == 7:
        return draw.choice([b"ppm:1500,1500\n", b"ppm:1500,1500,1500,1500,1500,1500,1500,15a0,",
                            b"ppm:15000,1500,1500,1500,1500,1500,1500,1500,", b"ppmx,",
                            b"ppm:,1500,1500,1500,1500,1500,1500,1500,"])
    if kind == 8:
        return b"t:0.1,x:0.5,"                              # fields swapped
    if kind == 9:
        return b"x:0.5,\x00t:0.1,"                          # NUL inside
    if kind == 10:
        return b"\r\n\r\n"                                  # empty lines: ignored
    if kind == 11:
        return b"X:0.5,T:0.1,"
    if kind == 12:
        return b"rp1.0,lp1.0" + bytes([draw.integer(128, 255)]) + b","
    return b",,,"


def param_command(draw: Draw) -> bytes:
    """``get:``/``set:`` of any parameter: in range, out of range, malformed, unknown."""
    p = draw.choice(DRAWN_PARAMS)
    name = p.name if draw.boolean(0.9) else draw.choice(["kp", "kp_x", "", "KP_L", p.name + "_"])
    if draw.boolean(0.25):
        return f"get:{name}".encode()
    kind = draw.integer(0, 5)
    if p.integer:
        value = draw.choice([str(draw.integer(int(p.low), int(p.high))), str(draw.integer(0, 9999)),
                             "0500", "00500", "", "5e2", "-200", "1500.0"])
    elif kind <= 2:
        value = f"{draw.real(float(p.low), float(p.high)):.{draw.integer(0, 6)}f}"
    elif kind == 3:
        value = decimal_text(draw, float(p.high) * 1.2, False)
    else:
        value = draw.choice(["", "-1", "nan", "inf", "1e2", "0", "1x", str(p.high), str(p.low)])
    sep = "=" if draw.boolean(0.95) else ":"
    return f"set:{name}{sep}{value}".encode()


def protocol_v2_command(draw: Draw) -> bytes:
    """``hello`` or ``hello:4``, ``estop``, ``reset``, a ``get:``/``set:`` (``param_command``), ``save``
    or ``defaults``. (``RandomDraw``'s 0..11 takes 4 bits, as 0..9 did: a seed's trace
    changes only where it now draws 10 or 11.)"""
    kind = draw.integer(0, 11 if getattr(draw, "eeprom_commands", True) else 9)
    if kind == 10:
        return b"save"
    if kind == 11:
        return b"defaults"
    if kind == 0:
        return b"hello:4" if draw.boolean(0.5) else b"hello"
    if kind == 1:
        return b"estop"
    if kind <= 3:
        return b"reset"
    return param_command(draw)


def framed(draw: Draw, body: bytes) -> bytes:
    """``body`` as a v3 frame, sometimes damaged: bit flips (the ``$`` too), a missing or
    lower-case CRC, a missing or bad sequence number, an overlong frame."""
    body = body.rstrip(b"\r\n")
    line = frame(body, draw.integer(0, SEQ_MAX))
    damage = draw.integer(0, 13)
    if damage == 0:
        for _ in range(draw.integer(1, 3)):
            i = draw.integer(0, len(line) - 2)
            line = line[:i] + bytes([line[i] ^ (1 << draw.integer(0, 6))]) + line[i + 1:]
    elif damage == 1:
        line = line[:-6] + b"\n"                           # no CRC
    elif damage == 2:
        line = line[:-5] + line[-5:-1].lower() + b"\n"    # lower-case hex: refused
    elif damage == 3:
        inner = draw.choice([b"123456:", b"70000:", b"12", b"", b":"]) + body
        line = b"$" + inner + b"*%04X\n" % crc16(inner)
    elif damage == 4:
        inner = b"1:" + body + b"," + b"9" * draw.integer(40, 70)
        line = b"$" + inner + b"*%04X\n" % crc16(inner)
    elif damage == 5:
        line = b"," + line[1:]                             # the $ -> , flip
    return line


def command(draw: Draw, travel_sign: list[int], said_hello: list[bool] | None = None) -> bytes:
    """One command of any kind; ``travel_sign`` tracks the direction so reversals
    (and so pivots) come often. A quarter are v3 frames, and after a ``hello``
    (``said_hello``, which this updates) nine in ten: the board then refuses unframed
    lines but stops and estop."""
    body = _command(draw, travel_sign)
    hello = said_hello is not None and said_hello[0]
    if draw.boolean(0.9 if hello else 0.25):
        line = framed(draw, body)
    else:
        line = body
    if said_hello is not None and b"hello" in line:
        said_hello[0] = True
    return line


def _command(draw: Draw, travel_sign: list[int]) -> bytes:
    kind = draw.integer(0, 11)
    if kind >= 10:
        return protocol_v2_command(draw) + b"\n"
    if kind <= 1:
        return malformed_command(draw)
    if kind == 2:
        return draw.choice([b"rp0,lp0,", b"x:0.000,t:0.000,", b"rp0.0,ln0.0,\n"])
    if kind == 3:
        return ppm_command(draw, lost=draw.boolean(0.3))
    if kind in (4, 5):
        travel_sign[0] = -travel_sign[0]
        speed = draw.real(0.05, 1.2) * travel_sign[0]
        return cmdvel_command(draw, x=speed)                # a reversal: pivot
    if kind == 6:
        return wheel_command(draw)
    if kind == 7:
        big = f"{draw.real(10.0, 17.59):.2f}"
        return wheel_command(draw, right=big, left=big)     # saturates when the wheels stay
    return cmdvel_command(draw)


def terminator(draw: Draw) -> bytes:
    """What ends a command: nothing (often), ``\\n``, ``\\r\\n`` or ``\\r``."""
    return draw.choice([b"", b"", b"\n", b"\r\n", b"\r"])


# ---- encoders ----------------------------------------------------------------
def encoder_motion(draw: Draw, duration: float) -> EdgeTrain:
    """Piecewise-constant speeds (counts/s, up to MAX_TRACE_EDGE_RATE), reversals,
    pauses, and now and then an illegal transition (both channels at once). The
    wheel rests until setup() has enabled the encoder interrupts."""
    times = [0.0, FIRST_COMMAND_S]
    counts = [0.0, 0.0]
    t = FIRST_COMMAND_S
    while t < duration:
        step = draw.real(0.02, 0.8)
        kind = draw.integer(0, 9)
        if kind <= 2:
            speed = 0.0
        elif kind == 3:
            speed = draw.choice([-1.0, 1.0]) * draw.real(28000.0, MAX_TRACE_EDGE_RATE)
        else:
            speed = draw.real(-15000.0, 15000.0)
        end = min(duration, t + step)
        times.append(end)
        counts.append(counts[-1] + speed * (end - t))
        t = end
    train = edges_from_trajectory(np.array(times), np.array(counts) + 0.5)
    if train.times.size and draw.boolean(0.4):
        train = _with_illegal(draw, train)
    return train


def _with_illegal(draw: Draw, train: EdgeTrain) -> EdgeTrain:
    """Replaces a few edges' states by the state two phases on: both pins change."""
    states = train.states.copy()
    for _ in range(draw.integer(1, 3)):
        i = draw.integer(0, states.size - 1)
        states[i] = state_for_count(_phase(states[i]) + 2)
    return EdgeTrain(train.times, states, train.start_count, train.end_count)


def storm(draw: Draw, encoders: dict[str, EdgeTrain],
          duration: float) -> tuple[dict[str, EdgeTrain], tuple[str, float, float]]:
    """One encoder with a burst of chatter in it: channel A toggling at 100,000 to
    500,000 edges/s for 2.5 to 20 ms (a loose connector, EMI), that wheel's own edges in
    the window dropped; the storm guard masks it within the first Timer0 period and the
    tick latches an implausible-encoder fault. The other wheel is still from just before
    the storm until the guard has surely tripped: its interrupts would compete with the
    storm's for those 0.6 ms, and the edges it would lose are beyond the decoder model's
    latency (the timing budget)."""
    side = draw.choice(["left", "right"])
    rate = draw.real(100_000.0, 500_000.0)
    length = draw.real(0.0025, 0.02)
    t0 = draw.real(0.1, max(0.1, duration - 0.1))
    n = max(2, int(rate * length) // 2 * 2)

    def cut(train: EdgeTrain, start: float, stop: float,
            inserted: tuple[np.ndarray, np.ndarray]) -> EdgeTrain:
        before, after = train.times < start, train.times > stop
        times = np.concatenate((train.times[before], inserted[0], train.times[after]))
        states = np.concatenate((train.states[before], inserted[1].astype(train.states.dtype),
                                 train.states[after]))
        return EdgeTrain(times, states, train.start_count, train.end_count)

    train = encoders[side]
    previous = train.states[train.times < t0]
    state = int(previous[-1]) if previous.size else 0b11
    toggles = np.where(np.arange(n) % 2 == 0, state ^ 0b10, state)
    out = dict(encoders)
    out[side] = cut(train, t0, t0 + n / rate, (t0 + np.arange(n) / rate, toggles))
    other = "right" if side == "left" else "left"
    empty = (np.zeros(0), np.zeros(0, dtype=np.uint8))
    out[other] = cut(encoders[other], t0 - 0.0002, t0 + 0.002, empty)
    return out, (side, t0, t0 + n / rate)


def burst(draw: Draw, travel_sign: list[int], said_hello: list[bool]) -> bytes:
    """20 to 150 commands back to back in one write: more than loop() can parse while a
    tick formats its lines, and answers enough to test the output budget."""
    return b"".join(command(draw, travel_sign, said_hello) + b"\n" for _ in range(draw.integer(20, 150)))


def _phase(state: int) -> int:
    return (0b11, 0b01, 0b00, 0b10).index(int(state))


# ---- whole trace -------------------------------------------------------------
def generate_trace(draw: Draw, duration: float) -> Trace:
    """A random trace of ``duration`` s (the module docstring lists what it covers)."""
    millis_start = None
    if draw.boolean(0.25):
        millis_start = 2**32 - draw.integer(0, 4000)
    serial: list[tuple[float, bytes]] = []
    t = FIRST_COMMAND_S + draw.real(0.0, 0.1)
    travel_sign = [1]
    said_hello = [False]
    while t < duration - 0.05:
        if draw.boolean(0.02):
            data = burst(draw, travel_sign, said_hello)
        else:
            data = command(draw, travel_sign, said_hello) + terminator(draw)
        serial.append((t, data))
        gap = draw.integer(0, 9)
        if gap == 0:
            t += draw.real(0.55, 1.5)        # silence past the watchdog
        elif gap <= 2:
            t += draw.real(0.0, 0.02)        # bursts: several commands within a tick
        else:
            t += draw.real(0.03, 0.35)       # inside a pivot, often
    if zlib.crc32(b"".join(data for _, data in serial)) % NEUTRAL_FIRST_EVERY != 1:
        serial = [(FIRST_COMMAND_S, b"rp0,lp0,\n")] + [
            (t + NEUTRAL_LEAD_S, data) for t, data in serial if t + NEUTRAL_LEAD_S < duration - 0.05]
    encoders = {side: encoder_motion(draw, duration) for side in ("left", "right")}
    storms = []
    if draw.boolean(0.12):
        encoders, where = storm(draw, encoders, duration)
        storms.append(where)
    # A seed's trace without a flood is the trace it was before floods.
    flooded = getattr(draw, "floods", True) and duration >= 1.5 and draw.boolean(0.1)
    if flooded:
        serial, encoders = flood(draw, serial, duration)
        storms = []
    trace = Trace(duration=duration, serial=serial, encoders=encoders, millis_start=millis_start,
                  storms=storms)
    # A quarter of the traces tell the board feedback_form 1 before their first command,
    # so that its feedback lines carry the wheels' tail while they are unframed (until a
    # hello:4, a reset that loads no saved form, or a set: or defaults of their own).
    # Chosen by the CRC of the writes drawn so far, not drawn, so that every seed draws
    # what it drew before (the seeds the tests name keep their traces).
    form_first = (getattr(draw, "feedback_forms", True)
                  and zlib.crc32(b"".join(data for _, data in serial)) % FEEDBACK_FORM_EVERY == 0)
    # The last draw: a seed's trace without a profile is the trace it was before them.
    if getattr(draw, "profiles", True) and not storms and not flooded and draw.boolean(PROFILE_P):
        trace = motion_profile(draw, trace)
    if form_first:
        trace.serial.insert(0, (FIRST_COMMAND_S, b"set:feedback_form=1\n"))
    # Inhibits from the same CRC, never drawn: a seed's writes and encoders stay its own
    # (and not in a motion profile, whose rule an inhibit's stop would cut short).
    crc = zlib.crc32(b"".join(data for _, data in serial))
    if getattr(draw, "inhibits", True) and trace.profile is None and crc % INHIBIT_EVERY == 2:
        trace.inhibits = inhibit_changes(np.random.default_rng(crc), duration)
        if (crc >> 9) % 2:              # and the brake's manual release (push mode) in half
            trace.inhibits = sorted(trace.inhibits + pin_pulls(np.random.default_rng(crc + 2), duration, 4))
    # A fitted brake, from the same CRC (a third of the traces, not a profile's: the hold's
    # rules want their duties), and its coil's status in half of those.
    if (getattr(draw, "brakes", True) and trace.profile is None
            and (crc // INHIBIT_EVERY) % BRAKE_FITTED_EVERY == 1):
        trace.serial.insert(0, (FIRST_COMMAND_S, b"set:brake_fitted=2\nset:brake_fitted=1\n"))
        if (crc >> 8) % 2:
            trace.inhibits = sorted(trace.inhibits + pin_pulls(np.random.default_rng(crc + 1), duration, 3))
    # A hot motor, from the same CRC (a quarter of the traces; not a profile's, whose rule
    # a rollback or a cut-off would cut short).
    if getattr(draw, "heats", True) and trace.profile is None and (crc >> 11) % HOT_EVERY == 1:
        trace.pokes = hot_windings(np.random.default_rng(crc + 3), duration)
    # The battery's voltage, from the same CRC (a third of the traces; not a profile's,
    # whose rule the low-battery rollback or the under-voltage fault would cut short).
    if getattr(draw, "supplies", True) and trace.profile is None and (crc >> 13) % SUPPLY_EVERY == 1:
        trace.supply = supply_changes(np.random.default_rng(crc + 4), duration)
    # The motors' currents, from the same CRC (a third of the traces; not a profile's).
    if getattr(draw, "currents", True) and trace.profile is None and (crc >> 15) % CURRENTS_EVERY == 1:
        held_against_a_wall(np.random.default_rng(crc + 5), trace)
    return trace


def supply_changes(rng: np.random.Generator, duration: float) -> list[tuple[float, int]]:
    """One to four changes of the battery's voltage over ``duration`` s, as (s, mV at A0,
    ``pin_millivolts``), in time order and at least ``SUPPLY_SPACING_S`` apart: seven in
    ten between 20 and 24.5 V (the filtered supply crosses ``BATTERY_CUTOFF_V``,
    ``BATTERY_LOW_V`` and ``BATTERY_LOW_END`` there, held long enough), the rest
    anywhere from a cut wire's 0 V to a charging battery's 29 V."""
    changes: list[tuple[float, int]] = []
    for _ in range(int(rng.integers(1, 5))):
        at = round(float(rng.uniform(0.05, max(0.06, duration - 0.05))), 4)
        volts = float(rng.uniform(20.0, 24.5) if rng.random() < 0.7 else rng.uniform(0.0, 29.0))
        changes.append((at, pin_millivolts(volts)))
    return spaced(changes, SUPPLY_SPACING_S)


def hot_windings(rng: np.random.Generator, duration: float) -> list[tuple[float, dict[str, float | int]]]:
    """The windings' estimates set once, at a time in the trace's first 80 %: each
    below the rollback, at its start (within 5 K either side), within it, or at the
    cut-off; the rollback flag on or off (on with both cool: its end comes next)."""
    edges = ((25.0, 105.0), (105.0, 115.0), (115.0, 124.0), (124.0, 130.0))

    def temp() -> float:
        lo, hi = edges[int(rng.integers(0, len(edges)))]
        return round(float(rng.uniform(lo, hi)), 3)

    at = round(float(rng.uniform(0.1, 0.8 * duration)), 4)
    hot: dict[str, float | int] = {"windingTempL": temp(), "windingTempR": temp(),
                                   "thermalRollback": int(rng.integers(0, 2))}
    return [(at, hot)]


def pin_pulls(rng: np.random.Generator, duration: float, number: int) -> list[tuple[float, int, bool]]:
    """One or two pulls of input ``number`` low (3: the brake driver's status, a glitch
    under BRAKE_STATUS_TICKS or a coil fault; 4: the brake's manual release, push mode),
    each let go after 0.01 to 1.5 s."""
    return _pulls(rng, duration, lambda: number)


def _pulls(rng: np.random.Generator, duration: float, which: Callable[[], int]
           ) -> list[tuple[float, int, bool]]:
    """One or two pulls low of the input ``which()`` names (asked first for each, so the
    draws come in the order they always did), each let go after 0.01 to 1.5 s (a glitch,
    or a pull held) unless the trace ends first; sorted by time."""
    changes: list[tuple[float, int, bool]] = []
    for _ in range(int(rng.integers(1, 3))):
        number = which()
        start = float(rng.uniform(0.05, max(0.06, duration - 0.1)))
        held = float(rng.choice([rng.uniform(0.01, 0.06), rng.uniform(0.1, 1.5)]))
        changes.append((round(start, 4), number, True))
        if start + held < duration:
            changes.append((round(start + held, 4), number, False))
    return sorted(changes)


def inhibit_changes(rng: np.random.Generator, duration: float) -> list[tuple[float, int, bool]]:
    """One to four changes of the inhibit inputs over ``duration`` s, (s, input, active):
    an input pulled low, let go after 0.01 to 1.5 s (a glitch under the debounce, or a
    charger plugged and pulled); both inputs at once at times."""
    return _pulls(rng, duration, lambda: int(rng.integers(1, 3)))


def flood(draw: Draw, serial: list[tuple[float, bytes]], duration: float
          ) -> tuple[list[tuple[float, bytes]], dict[str, EdgeTrain]]:
    """The trace's last second or so a flood: ``hello:4``, then 100 to 250 long ``set:``
    and ``get:`` frames back to back on the wire, while both wheels turn at 25,000 edges/s
    or more from the start. loop() falls behind now and then (a tick formats its lines
    while a ``set:`` is parsed and answered) and the RX ring overflows: bytes lost,
    marked, counted and answered ``ERR:overrun``. Bursts alone no longer lose a byte since
    the interrupts got faster. Returns the serial writes before the flood and
    the flood, and the encoders' motion."""
    start = duration - draw.real(0.9, 1.4)
    frames = [frame(b"hello:4", draw.integer(0, SEQ_MAX))]
    floats = [p for p in PARAMS if not p.integer]
    for _ in range(draw.integer(100, 250)):
        p = draw.choice(floats)
        body = (f"get:{p.name}" if draw.boolean(0.3) else
                f"set:{p.name}={draw.integer(0, 20)}.{_digits(draw, 15, 25)}")
        frames.append(frame(body.encode(), draw.integer(0, SEQ_MAX)))
    writes = [(t, data) for t, data in serial if t < start] + [(start, b"".join(frames))]
    encoders = {}
    for side in ("left", "right"):
        rate = draw.choice([-1.0, 1.0]) * draw.real(25000.0, MAX_TRACE_EDGE_RATE)
        travel = rate * (duration - FIRST_COMMAND_S)
        encoders[side] = edges_from_trajectory(np.array([0.0, FIRST_COMMAND_S, duration]),
                                               np.array([0.5, 0.5, 0.5 + travel]))
    return writes, encoders
