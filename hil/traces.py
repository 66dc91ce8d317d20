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
estop), get/set of every parameter in and out of range, estop and reset; bursts of
20 to 150 commands back to back (the output budget is spent), floods of long ``set:``
frames at top speed (``flood``: loop() falls behind, received bytes are lost and
accounted for) and encoder storms of 60,000 to 500,000 edges/s (the storm guard, the
implausible-encoder fault). The encoders are scripted, not driven by the duty, so the
rules that read the duty against the wheels' speeds (the grade limit, a dead motor, an
overspeed, the hill hold) get motion profiles that look like them: a trace may end in
one (``motion_profile``, ``PROFILES``).
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from wcdrive.firmware.constants import ACCEL_MAX, CPR, MAX_ACCEL, TWO_PI
from wcdrive.firmware.params import PARAMS
from wcdrive.plant.encoders import STATE_OF_PHASE, EdgeTrain, edges_from_trajectory, state_for_count
from wcdrive.protocol.codec import SEQ_MAX, crc16, frame

T = TypeVar("T")

#: When the first byte may arrive: setup() is done after about 2 ms.
FIRST_COMMAND_S = 0.010
#: Edges/s per wheel in generated traces. The firmware counts every edge up to
#: 70,000 edges/s on both wheels at once, coincident edges included (the timing budget:
#: tests/boards/test_harness.py); traces keep a margin for the UART interrupts.
MAX_TRACE_EDGE_RATE = 60000.0


class Draw(Protocol):
    """A source of choices: ``RandomDraw`` or ``HypothesisDraw``."""

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi]."""

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p``."""


class RandomDraw:
    """Choices from ``random.Random(seed)``: one seed, one trace."""

    def __init__(self, seed: int, *, eeprom_commands: bool = True, floods: bool = True,
                 profiles: bool = True) -> None:
        """``eeprom_commands=False``: the generator as it was before ``save`` and
        ``defaults``; ``floods=False``: as it was before ``flood``; ``profiles=False``:
        as it was before ``motion_profile``; so that a seed found then gives the same
        trace."""
        self.rng = random.Random(seed)
        self.eeprom_commands = eeprom_commands
        self.floods = floods
        self.profiles = profiles

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""
        return self.rng.randint(lo, hi)

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi]."""
        return self.rng.uniform(lo, hi)

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""
        return options[self.rng.randrange(len(options))]

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p``."""
        return self.rng.random() < p


class HypothesisDraw:
    """Choices drawn from ``st.data()``, so hypothesis can shrink a failing trace."""

    def __init__(self, data: Any) -> None:
        from hypothesis import strategies as st

        self._st = st
        self._data = data

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""
        return self._data.draw(self._st.integers(lo, hi))

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi] (never NaN)."""
        return self._data.draw(self._st.floats(lo, hi, allow_nan=False))

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""
        return options[self._data.draw(self._st.integers(0, len(options) - 1))]

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p`` (in steps of 0.001)."""
        return self._data.draw(self._st.integers(0, 999)) < int(p * 1000)


@dataclass
class Trace:
    """The firmware's inputs: serial writes as (s, bytes), an encoder edge train per
    side, and ``millis_start``, the ``millis()`` set at ``main()`` (None: boot at 0)."""

    duration: float
    serial: list[tuple[float, bytes]] = field(default_factory=list)
    encoders: dict[str, EdgeTrain] = field(default_factory=dict)
    millis_start: int | None = None
    #: Encoder storms in the trains (``storm``): (side, start s, end s).
    storms: list[tuple[str, float, float]] = field(default_factory=list)
    #: The EEPROM's contents at power-on (``EEPROM_SIZE`` bytes; None: erased).
    eeprom: bytes | None = None
    #: Resets of the board during the trace (``VirtualMega.reset``): (s, cause).
    resets: list[tuple[float, str]] = field(default_factory=list)
    #: The motion profile the trace ends in (one of ``PROFILES``; None: none), and from when.
    profile: str | None = None
    profile_start: float = 0.0

    def describe(self) -> str:
        """The trace as text for a failure report, one serial write a line."""
        lines = [f"duration={self.duration}s millis_start={self.millis_start}"]
        if self.profile is not None:
            lines.append(f"  ends in the motion profile {self.profile!r} from t={self.profile_start:.4f}s")
        if self.eeprom is not None:
            lines.append(f"  EEPROM at power-on: {self.eeprom[:48].hex()}...")
        lines += [f"  t={t:.4f}s {data!r}" for t, data in self.serial]
        for side, train in self.encoders.items():
            lines.append(f"  {side}: {train.times.size} edges, count {train.start_count}"
                         f" -> {train.end_count}")
        lines += [f"  reset ({cause}) at t={t:.4f}s" for t, cause in self.resets]
        lines += [f"  storm on {side} from {a:.4f}s to {b:.4f}s" for side, a, b in self.storms]
        return "\n".join(lines)


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
    p = draw.choice(PARAMS)
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
    # The last draw: a seed's trace without a profile is the trace it was before them.
    if getattr(draw, "profiles", True) and not storms and not flooded and draw.boolean(PROFILE_P):
        trace = motion_profile(draw, trace)
    return trace


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
    if not at_boot:
        script.send(draw, t0, b"defaults")
        script.send(draw, t0 + 0.005, b"estop")
        script.send(draw, t0 + 0.7, b"reset")
        script.send(draw, t0 + PREAMBLE_S - 0.05, b"reset")
        script.send(draw, t0 + PREAMBLE_S - 0.03, b"rp0,lp0,")
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
