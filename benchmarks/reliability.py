"""Reliability benchmark for protocol v3: the Python port and the compiled
firmware in simavr take the same hostile input, and nothing but a valid command moves
the chair. docs/benchmarks.md ("Reliability (protocol v3)") keeps the figures.

    python benchmarks/reliability.py [--quick] [--seed N] [--no-simavr]
        [--port-lines N] [--port-frames N] [--legacy-frames N]
        [--firmware-lines N] [--firmware-frames N] [--r3-trials N] [--r3-pace X]

R1, random and mutated lines. Every line ends in ``\\n``, so each starts with an empty
command buffer. Sources: random bytes (30 %), mutations of valid commands (55 %: bit
flips, byte replacements, insertions, deletions, truncations, duplications, splices
of two commands, swapped bytes, toggled case and, after hello, a frame stripped to its
bare command), and valid commands as controls (15 %: motions, stops, PPM loss and,
after hello, get/set). 80 % of the lines go to a board that said hello (strict), 20 %
to one that did not (legacy, version 1).

* Valid input, decided by an oracle written from protocol/PROTOCOL.md and not from the
  parser: the line is cut into commands by the rules of "Framing and commands" (a
  command ends at a line end, or at the comma of its last field unless it starts
  with ``$``; more than 63 bytes is overlong). After hello a line is valid when one
  of its commands is a v3 frame with the right CRC-16 (``$<1-5 digits>:<...>*<4 upper
  hex>``, seq <= 65535, at most 63 bytes). Before hello it is valid when one of its
  commands is a well-formed version-1 command (WHEEL, CMDVEL within range, PPM with
  eight 1-4 digit channels, hello, estop, reset, get:, set:) or such a frame. The
  oracle errs on the side of "valid" at the range limits (1e-6 relative).
* A motion from invalid input: a line the oracle calls invalid after which the chair
  is commanded to move (a non-zero wheel target, or a pivot under way) and the line
  either changed the commanded motion (mode, targets, pivot phase, pending targets)
  or was accepted as a command (``cmdSinceTick`` set, which re-arms the watchdog).
  Stops are not motions: after hello a bare ``x:0,t:0,`` or PPM loss frame is still
  accepted, by design. Parameter changes from invalid lines are counted too.
* On the port every line is fed to ``Firmware.feed`` and a 50 ms tick follows it, so
  each line gets its answers (3 per tick) and ``cmdSinceTick`` starts at 0. A crash is
  an exception; a hang a line that takes more than 50 ms (one control period).
* On the firmware the lines go in chunks, each on a freshly booted board in simavr, at
  wire speed (with a pause after 1 line in 20), through ``wcdrive.hil.lockstep``:
  ``record`` stops at every ``processByte`` and ``controlTick`` (and finishes the
  event under way when the trace ends), ``compare`` feeds
  the same events to the port and compares every global after every event, PWM and
  DIR, and the whole TX stream (port = firmware). The motion check runs on the
  firmware's own SRAM after each byte. A crash is the AVR core stopping or a second
  BOOT line; a hang a byte that never reaches ``processByte`` or waits more than 50 ms
  for it, or a missed tick (two ticks 100 ms apart).

R2, corrupted frames: CMDVEL frames (random x/t, random seq) with 1, 2 or 3 flipped
bits, or a burst of 2 to 16 bits (first and last flipped, the middle random) counted
in the CRC's bit order (MSB first) or in the UART's (LSB first), anywhere in the line
but its final ``\\n`` (the ``$``, ``*``, CRC digits and seq included), sent after
hello. None may be executed (any change of motion, parameters or e-stop, or an
accepted command) or ACKed, and every command they split into must be refused. For
comparison, the same corruptions of the bare v1 line ``x:...,t:...,\\n`` before
hello (what a seed host without hello risks), and of a v2 frame ``$seq:cmd*hh`` with
the XOR checksum, in a model: the port before hello with the CRC check replaced by
v2's (either-case hex XOR); v2 boards also took unframed lines after hello, as the
port takes them before. Each of these trials starts on a fresh board at rest.

R3, faults mid-motion (``firmware_r3``): the firmware in simavr with the chair on its
pins (``MegaBoard``, paced to real time, or ``--r3-pace`` times it with the host's
clock stretched alike), behind a ``FaultyLink`` (the USB cable), driven by a
``Wheelchair`` with ``set_velocity`` at 20 Hz at 0.4-1.2 m/s for 0.6-1.0 s; then, at
a random moment between two commands, one of: the link cut both ways while the port
stays open (mid-line when a write is under way), the device unplugged (reads, writes
and reopening raise; replugged, opening the port pulses DTR and resets the board, as
on a real Mega), or a DTR reset (``MegaBoard.reset``). The host commands on until it
notices (``LinkLost``, a refused motion call, or ``BOARD_RESET``), then waits until the
chair has been still and unpowered for 0.1 s; the link comes back and the host must
drive again (after a reset or a replug: once the board answered a new hello). Per
trial: PWM 0 for good against ``stop_bound`` (the watchdog, the ramp at the emergency
deceleration, two ticks; after a reset no watchdog, and PWM 0 from its first
instruction), the standstill, the travel against issue 13's distance goal, when the
host noticed and drove again, the reboot cause it saw, and the frames the board
executed after a reset before a new hello; over the run, the frames executed twice
(an ``ACK:`` of one sequence number twice).
"""

from __future__ import annotations

import argparse
import math
import random
import re
import sys
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from wcdrive.firmware import commands
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.params import PARAMS
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import crc16, frame
from wcdrive.protocol.spec import integer, real

if TYPE_CHECKING:
    from wcdrive.boards.simavr.mega_board import MegaBoard
    from wcdrive.boards.simavr.virtual_mega import VirtualMega
    from wcdrive.hil.lockstep import Recording

ElfPath = str | Path | None
Sram = dict[str, float | int]

CMD_MAX_LEN = integer("CMD_MAX_LEN")
SEQ_MAX = integer("SEQ_MAX")
MAX_LINEAR = real("MAX_LINEAR")
MAX_ANGULAR = real("MAX_ANGULAR")
MAX_WHEEL = real("MAX_WHEEL_SPEED")
HELLO_FRAME = frame(b"hello", 1)
TICK_MS = 50
HANG_S = 0.050                      # a line (port) or a byte (firmware) must be done within a tick

QUICK = {"port_lines": 20_000, "port_frames": 20_000, "legacy_frames": 20_000,
         "firmware_lines": 600, "firmware_frames": 400, "r3_trials": 5}
FULL = {"port_lines": 1_000_000, "port_frames": 1_000_000, "legacy_frames": 1_000_000,
        "firmware_lines": 100_000, "firmware_frames": 10_000, "r3_trials": 100}


# ---- input -----------------------------------------------------------------------
_FORMATS = ("%.3f", "%.3f", "%.3f", "%.2f", "%.1f", "%.4f")


def _number(rng: random.Random, lo: float, hi: float, signed: bool) -> bytes:
    """A non-zero decimal in [lo, hi] (either sign with ``signed``)."""
    while True:
        v = rng.uniform(lo, hi)
        if signed and rng.random() < 0.5:
            v = -v
        text = (rng.choice(_FORMATS) % v).encode()
        if float(text) != 0.0:
            return text


def motion_command(rng: random.Random) -> bytes:
    """A valid command that drives (non-zero targets), well inside every limit."""
    k = rng.random()
    if k < 0.45:
        x = _number(rng, 0.0, 2.6, True)
        t = _number(rng, 0.0, 9.3, True) if rng.random() < 0.8 else b"0"
        return b"x:%s,t:%s," % (x, t)
    if k < 0.8:
        return b"r%c%s,l%c%s," % (rng.choice(b"pn"), _number(rng, 0.01, 17.5, False),
                                   rng.choice(b"pn"), _number(rng, 0.01, 17.5, False))
    channels = [rng.randint(1000, 2000) for _ in range(8)]
    channels[1] = 1500 + rng.choice((-1, 1)) * rng.randint(20, 500)   # stick out of the dead band
    return b"ppm:" + b",".join(b"%d" % c for c in channels) + b","


def stop_command(rng: random.Random) -> bytes:
    """A valid stop: zero targets in any form, or a PPM frame that reports signal loss."""
    k = rng.randrange(4)
    if k == 0:
        return rng.choice([b"x:0,t:0,", b"x:0.000,t:0.000,", b"x:-0.0,t:+0,", b"rp0,ln0.0,",
                           b"rn0.000,lp0,"])
    channels = [rng.randint(1000, 2000) for _ in range(8)]
    channels[1] = rng.randint(1490, 1510)
    channels[3] = rng.randint(1490, 1510)
    if k == 3:
        channels[rng.randrange(8)] = rng.choice([0, 850, 899, 2101, 9999])
    return b"ppm:" + b",".join(b"%d" % c for c in channels) + b","


_SETTABLE = [p for p in PARAMS if p.name != "max_wheel"]   # lowering it would refuse controls


def param_command(rng: random.Random) -> bytes:
    """``get:`` or ``set:`` (in range) of a parameter other than ``max_wheel``."""
    p = rng.choice(_SETTABLE)
    if rng.random() < 0.4:
        return b"get:" + p.name.encode()
    if p.integer:
        value = b"%d" % rng.randint(int(p.low), int(p.high))
    else:
        value = b"%.3f" % rng.uniform(float(p.low) + 0.001, float(p.high) - 0.001)
    return b"set:" + p.name.encode() + b"=" + value


def valid_line(rng: random.Random, strict: bool) -> tuple[str, bytes, bytes]:
    """(kind, content, terminator) of a valid command: a frame after hello (``strict``),
    a bare version-1 command before, newline-less (the seed host's way) or not."""
    r = rng.random()
    if r < 0.7:
        kind, cmd = "drive", motion_command(rng)
    elif strict and r < 0.85:
        kind, cmd = "param", param_command(rng)
    else:
        kind, cmd = "stop", stop_command(rng)
    if strict:
        return kind, frame(cmd, rng.randint(0, SEQ_MAX))[:-1], b"\n"
    return kind, cmd, rng.choice([b"", b"\n", b"\r\n"])


_ALPHABET = b"0123456789.,:-+$*xtrlpnm\r\n ABCDEFabcdef=_eshogk"


def _random_byte(rng: random.Random) -> int:
    return rng.randrange(256) if rng.random() < 0.4 else rng.choice(_ALPHABET)


MUTATIONS = ("flip", "replace", "insert", "delete", "truncate", "duplicate", "splice", "swap",
             "case")


def mutate(rng: random.Random, content: bytes, other: bytes, strict: bool) -> tuple[str, bytes]:
    """A mutation of a valid command's ``content`` (``other``: a second one, to splice)."""
    op = rng.choice(MUTATIONS + (("deframe",) if strict else ()))
    c = bytearray(content)
    n = len(c)
    if op == "flip":
        for _ in range(rng.randint(1, 3)):
            c[rng.randrange(n)] ^= 1 << rng.randrange(8)
    elif op == "replace":
        for _ in range(rng.randint(1, 3)):
            c[rng.randrange(n)] = _random_byte(rng)
    elif op == "insert":
        for _ in range(rng.randint(1, 3)):
            c.insert(rng.randint(0, len(c)), _random_byte(rng))
    elif op == "delete":
        i = rng.randrange(n)
        del c[i:i + rng.choice((1, 1, 2, 3, rng.randint(1, n)))]
    elif op == "truncate":
        c = c[:rng.randrange(n)]
    elif op == "duplicate":
        if rng.random() < 0.3:
            c = c + rng.choice((b"", b",")) + c
        else:
            i = rng.randrange(n)
            j = rng.randint(i + 1, n)
            c[j:j] = c[i:j]
    elif op == "splice":
        c = c[:rng.randint(1, n - 1)] + other[rng.randint(1, len(other) - 1):]
    elif op == "swap":
        i = rng.randrange(n - 1)
        c[i], c[i + 1] = c[i + 1], c[i]
    elif op == "case":
        letters = [i for i, b in enumerate(c) if 0x41 <= (b | 0x20) - 0x20 <= 0x5A]
        c[rng.choice(letters)] ^= 0x20
    else:                                   # deframe: the bare command of a frame
        c = c[c.index(b":") + 1:c.rindex(b"*")]
    if bytes(c) == content:
        c[rng.randrange(n)] ^= 1 << rng.randrange(8)
    return op, bytes(c)


def random_line(rng: random.Random) -> bytes:
    """1 to 90 random bytes (any byte, printable ASCII, or the protocol's characters), then
    ``\\n``."""
    n = rng.choice((rng.randint(1, 8), rng.randint(9, 40), rng.randint(9, 40), rng.randint(41, 90)))
    k = rng.random()
    if k < 0.4:
        body = rng.randbytes(n)
    elif k < 0.7:
        body = bytes(rng.randint(0x21, 0x7E) for _ in range(n))
    else:
        body = bytes(rng.choice(_ALPHABET) for _ in range(n))
    return body + b"\n"


def r1_lines(rng: random.Random, n: int, strict: bool) -> Iterator[tuple[str, bytes]]:
    """``n`` lines as (source, bytes): source "random", "mutated", or the valid kinds
    "drive", "stop", "param"."""
    for _ in range(n):
        r = rng.random()
        if r < 0.30:
            yield "random", random_line(rng)
        elif r < 0.85:
            _, content, _ = valid_line(rng, strict)
            _, other, _ = valid_line(rng, strict)
            yield "mutated", mutate(rng, content, other, strict)[1] + b"\n"
        else:
            kind, content, end = valid_line(rng, strict)
            yield kind, content + end


def cmdvel_command(rng: random.Random) -> bytes:
    """R2's command: ``x:<v>,t:<w>,`` with 3 decimals, as the seed host sends it."""
    return b"x:%.3f,t:%.3f," % (rng.uniform(-2.6, 2.6), rng.uniform(-2.0, 2.0))


CORRUPTIONS = ("1 bit", "2 bits", "3 bits", "burst, CRC bit order", "burst, UART bit order")


def corrupt(rng: random.Random, line: bytes) -> tuple[str, bytes]:
    """(class, line) with 1-3 flipped bits or a 2-16 bit burst anywhere but the final
    ``\\n``. Bits are numbered MSB first in each byte (the CRC's order) or LSB first
    (the UART's, for the second kind of burst)."""
    out = bytearray(line)
    bits = 8 * (len(line) - 1)
    kind = rng.choice(CORRUPTIONS)
    if kind.startswith("burst"):
        width = rng.randint(2, 16)
        start = rng.randint(0, bits - width)
        pattern = rng.getrandbits(width) | 1 | (1 << (width - 1))
        positions = [start + j for j in range(width) if pattern >> j & 1]
    else:
        positions = rng.sample(range(bits), int(kind[0]))
    uart = kind.endswith("UART bit order")
    for k in positions:
        out[k // 8] ^= (1 << (k % 8)) if uart else (0x80 >> (k % 8))
    return kind, bytes(out)


# ---- the oracle: valid input, from protocol/PROTOCOL.md ------------------------------
_EOL = re.compile(rb"[\r\n]")


def split_commands(line: bytes) -> list[bytes | None]:
    """The commands a line makes, by the framing rules (None: an overlong command)."""
    out: list[bytes | None] = []
    for seg in _EOL.split(line):
        p, n = 0, len(seg)
        while p < n:
            if seg[p] == 0x24:                              # a frame: to the line end
                out.append(seg[p:] if n - p <= CMD_MAX_LEN else None)
                break
            commas, i = 0, p
            while True:
                q = seg.find(b",", i)
                last = q if q >= 0 else n - 1
                if last >= p + CMD_MAX_LEN:                 # byte p+63 finds the buffer full
                    out.append(None)
                    k = p + CMD_MAX_LEN
                    if seg[k] == 0x2C:
                        p = k + 1
                    else:                                   # dropped up to the next comma
                        q2 = seg.find(b",", k + 1)
                        p = n if q2 < 0 else q2 + 1
                    break
                if q < 0:
                    out.append(seg[p:])
                    p = n
                    break
                commas += 1
                buf = seg[p:q + 1]
                need = 2 if buf[:1] in (b"r", b"x") else 8 if buf[:4] == b"ppm:" else 0
                if need == 0 or commas >= need:
                    out.append(buf)
                    p = q + 1
                    break
                i = q + 1
    return out


_U = rb"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_WHEEL = re.compile(rb"r[pn](" + _U + rb"),l[pn](" + _U + rb"),?")
_CMDVEL = re.compile(rb"x:([+-]?" + _U + rb"),t:([+-]?" + _U + rb"),?")
_PPM = re.compile(rb"ppm:\d{1,4}(?:,\d{1,4}){7},?")
_OTHER = re.compile(rb"hello|estop|reset|get:[\x21-\x7e]*|set:[\x21-\x7e]*")
_FRAME = re.compile(rb"\$(\d{1,5}):.*\*([0-9A-F]{4})", re.S)


def _within(text: bytes, limit: float) -> bool:
    return abs(float(text)) <= limit * (1 + 1e-6)


def frame_valid(cmd: bytes) -> bool:
    """A v3 frame with a well-formed seq and the right CRC-16, at most 63 bytes."""
    m = _FRAME.fullmatch(cmd)
    return (m is not None and len(cmd) <= CMD_MAX_LEN and int(m[1]) <= SEQ_MAX
            and crc16(cmd[1:-5]) == int(m[2], 16))


def v1_valid(cmd: bytes) -> bool:
    """A well-formed version-1 command (or a valid frame)."""
    m = _CMDVEL.fullmatch(cmd)
    if m:
        return _within(m[1], MAX_LINEAR) and _within(m[2], MAX_ANGULAR)
    m = _WHEEL.fullmatch(cmd)
    if m:
        return _within(m[1], MAX_WHEEL) and _within(m[2], MAX_WHEEL)
    return bool(_PPM.fullmatch(cmd) or _OTHER.fullmatch(cmd)) or frame_valid(cmd)


def line_valid(line: bytes, strict: bool) -> bool:
    """Does the line hold a valid command (after hello: a valid frame)?"""
    check = frame_valid if strict else v1_valid
    return any(c is not None and check(c) for c in split_commands(line))


# ---- what a line did -------------------------------------------------------------
Motion = tuple[int, float, float, int, float, float]
_PARAM_FIELDS = tuple(p.field for p in PARAMS)



def motion_of(s: FirmwareState) -> Motion:
    """The commanded motion: mode, targets, and the pivot with its pending targets."""
    pivot = s.pivotPhase
    return (s.mode, s.targetL, s.targetR, pivot, s.pendingL if pivot else 0.0,
            s.pendingR if pivot else 0.0)


def motion_in(d: dict[str, float | int]) -> Motion:
    """``motion_of`` for a lock-step snapshot of the firmware's SRAM."""
    pivot = int(d["pivotPhase"])
    return (int(d["mode"]), float(d["targetL"]), float(d["targetR"]), pivot,
            float(d["pendingL"]) if pivot else 0.0, float(d["pendingR"]) if pivot else 0.0)


def is_stop(m: Motion) -> bool:
    """No wheel target and no pivot under way."""
    return m[1] == 0.0 and m[2] == 0.0 and m[3] == 0


def params_of(s: FirmwareState) -> tuple[float | int, ...]:
    return tuple(getattr(s, f) for f in _PARAM_FIELDS)


def answer_kinds(out: bytes) -> list[str]:
    """The answers in a chunk of output (feedback, TLM and BOOT lines left out)."""
    kinds = []
    for line in out.split(b"\r\n"):
        head = line[:4]
        if head in (b"ERR:", b"EVT:"):
            kinds.append(line.decode("latin-1"))
        elif head == b"ACK:":
            kinds.append("ACK")
        elif head == b"NAK:":
            kinds.append("NAK:" + line.split(b",", 1)[1].decode("latin-1"))
        elif head == b"PAR:":
            kinds.append("PAR")
        elif line.startswith(b"HELLO:"):
            kinds.append("HELLO")
    return kinds


# ---- results -------------------------------------------------------------------
@dataclass
class Lockstep:
    """Lock-step totals over the simavr runs of one test."""

    runs: int = 0
    events: int = 0
    ticks: int = 0
    fields: int = 0
    tx_bytes: int = 0
    mismatches: int = 0
    examples: list[str] = field(default_factory=list)
    max_latency_s: float = 0.0      # a byte on the wire to its processByte
    max_tick_gap_ms: int = 0
    lost_bytes: int = 0
    extra_boots: int = 0


@dataclass
class R1Slice:
    """R1 on one side, for the lines sent after hello (strict) or before (legacy)."""

    lines: Counter[str] = field(default_factory=Counter)      # by source
    invalid: int = 0
    invalid_motions: int = 0
    invalid_param_changes: int = 0
    mutated_valid: int = 0              # mutations that are valid input (oracle)
    mutated_valid_drove: int = 0
    controls: Counter[str] = field(default_factory=Counter)   # valid lines by kind
    controls_ok: Counter[str] = field(default_factory=Counter)
    answers: Counter[tuple[str, str]] = field(default_factory=Counter)   # (group, kind)
    silent: Counter[str] = field(default_factory=Counter)    # lines without an answer, by group
    suppressed: int = 0
    crashes: int = 0
    hangs: int = 0
    worst_s: float = 0.0
    examples: list[str] = field(default_factory=list)
    lockstep: Lockstep | None = None

    @property
    def total(self) -> int:
        return sum(self.lines.values())


@dataclass
class R2Result:
    """R2 on one side."""

    frames: Counter[str] = field(default_factory=Counter)    # by corruption
    executed: Counter[str] = field(default_factory=Counter)
    acked: Counter[str] = field(default_factory=Counter)
    commands: int = 0                    # commands the frames split into (oracle)
    refused: int = 0                     # of those, refused (rejectedCount)
    answers: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    hangs: int = 0
    worst_s: float = 0.0
    examples: list[str] = field(default_factory=list)
    lockstep: Lockstep | None = None


@dataclass
class Legacy:
    """Outcomes of corrupted lines on a board that never said hello (v1), and in the v2
    model: by corruption, "refused", "same" (the intended motion), "different" (another
    motion), "stop"."""

    v1: Counter[tuple[str, str]] = field(default_factory=Counter)
    v2: Counter[tuple[str, str]] = field(default_factory=Counter)
    v2_acked_different: Counter[str] = field(default_factory=Counter)
    frames: Counter[str] = field(default_factory=Counter)        # v1 lines by corruption
    frames_v2: Counter[str] = field(default_factory=Counter)


@dataclass
class Results:
    """Everything one run measured, with the wall time of each part."""

    seed: int
    counts: dict[str, int]
    r1_port: dict[str, R1Slice] = field(default_factory=dict)
    r1_firmware: dict[str, R1Slice] = field(default_factory=dict)
    r2_port: R2Result | None = None
    r2_firmware: R2Result | None = None
    legacy: Legacy | None = None
    r3: R3Result | None = None
    wall: dict[str, float] = field(default_factory=dict)


# ---- R1 on the port ----------------------------------------------------------------
class _PortBoard:
    """A port ``Firmware`` with its clock and the chair (``wcdrive.plant``) on its
    motors: at each tick the plant has run the 50 ms since the last under the duty that
    tick set, and the encoders count its wheels. R1 tests the parser: the random
    command stream whips the chair about (a new motion every 50 ms) until the encoder
    fault checks take a wheel for reversed or stalled, which latches a fault
    that refuses motion until a ``reset`` once parked; so a latched fault is cleared
    after its tick (``faults`` counts them). ``strict`` says hello first."""

    def __init__(self, strict: bool) -> None:
        from wcdrive.plant import ChairParams, Plant

        self.fw = Firmware()
        self.now = 0
        self.faults = 0
        self.plant = Plant(ChairParams())
        self._scale = self.plant.p.counts_per_rev / (2.0 * math.pi)
        if strict:
            self.fw.feed(HELLO_FRAME)
            self.tick()

    def tick(self) -> None:
        s = self.fw.state
        self.plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
        recorded = self.plant.advance(TICK_MS, 0.001, record=True)
        assert recorded is not None
        left, right = recorded[0][-1]
        self.now += TICK_MS
        # as wcdrive.boards.simavr.plant_on_pins counts them: the left encoder counts down forward
        self.fw.tick(self.now, math.floor(-left * self._scale + 0.5), math.floor(right * self._scale + 0.5))
        if getattr(s, "faultFlags", 0):
            self.faults += 1
            s.faultFlags = 0


def _check_line(st: R1Slice, source: str, line: bytes, strict: bool, drove: bool,
                accepted: bool, params_changed: bool, answers: list[str] | None,
                stopped: bool, check: bool = True) -> None:
    """Books one line's outcome (``answers`` None: not attributed to the line; ``check``
    False: counted only)."""
    st.lines[source] += 1
    if not check:
        return
    if source in ("random", "mutated"):
        if line_valid(line, strict):
            if source == "mutated":
                st.mutated_valid += 1
                st.mutated_valid_drove += drove
        else:
            st.invalid += 1
            if drove or params_changed:
                st.invalid_motions += drove
                st.invalid_param_changes += params_changed
                if len(st.examples) < 10:
                    st.examples.append(f"{'strict' if strict else 'legacy'} {source} {line!r}: "
                                       f"{'drove' if drove else 'changed a parameter'}")
        return
    st.controls[source] += 1
    if source == "drive":
        ok = drove
    elif source == "stop":
        ok = accepted and stopped
    else:
        ok = answers is None or "PAR" in answers
    if strict and answers is not None:
        ok = ok and "ACK" in answers
    if ok:
        st.controls_ok[source] += 1
    elif len(st.examples) < 10:
        st.examples.append(f"valid {source} {line!r} not carried out: {answers}")


def port_r1(n: int, rng: random.Random, strict: bool) -> R1Slice:
    """R1 on the port: ``n`` lines, a tick after each."""
    st = R1Slice()
    board = _PortBoard(strict)
    clock = time.perf_counter
    for source, line in r1_lines(rng, n, strict):
        s = board.fw.state
        m0, p0, sup0 = motion_of(s), params_of(s), s.errSuppressed
        t0 = clock()
        try:
            out = board.fw.feed(line)
        except Exception as error:                      # a crash: book it, boot again
            st.crashes += 1
            st.lines[source] += 1
            if len(st.examples) < 10:
                st.examples.append(f"crash on {line!r}: {error!r}")
            board = _PortBoard(strict)
            continue
        dt = clock() - t0
        st.worst_s = max(st.worst_s, dt)
        st.hangs += dt > HANG_S
        m1 = motion_of(s)
        accepted = bool(s.cmdSinceTick)
        drove = not is_stop(m1) and (m1 != m0 or accepted)
        kinds = answer_kinds(out)
        group = source if source in ("random", "mutated") else "valid"
        for kind in kinds:
            st.answers[group, kind] += 1
        if not kinds:
            st.silent[group] += 1
        st.suppressed += s.errSuppressed - sup0
        _check_line(st, source, line, strict, drove, accepted, params_of(s) != p0, kinds,
                    is_stop(m1))
        board.tick()
    return st


# ---- the firmware in simavr, through the lock-step harness ---------------------------
def _wire(chunks: list[tuple[float, bytes]]) -> tuple[list[tuple[float, bytes]], list[int], int]:
    """Serial writes for a trace from (pause before it in s, bytes), the first 10 ms after
    reset, with every byte's cycle on the wire as ``VirtualMega.send`` queues them, and
    the cycle at which the wire is free."""
    from wcdrive.avr.uart import UART_BYTE_CYCLES
    from wcdrive.boards.simavr.virtual_mega import F_CPU

    writes: list[tuple[float, bytes]] = []
    cycles: list[int] = []
    free = round(0.010 * F_CPU)
    for pause, data in chunks:
        start = free + round(pause * F_CPU)
        writes.append((start / F_CPU, data))
        cycles.extend(start + i * UART_BYTE_CYCLES for i in range(len(data)))
        free = start + len(data) * UART_BYTE_CYCLES
    return writes, cycles, free


def _lockstep_run(chunks: list[tuple[float, bytes]], elf: ElfPath,
                  totals: Lockstep) -> tuple[Recording | None, list[int]]:
    """Runs the bytes on the firmware and compares with the port; returns the recording
    (None when the AVR core crashed) and each byte's cycle on the wire."""
    from wcdrive.boards.simavr.virtual_mega import F_CPU, HarnessError
    from wcdrive.hil.lockstep import compare, record
    from wcdrive.hil.traces import Trace

    writes, cycles, free = _wire(chunks)
    # Two ticks past the last byte: every byte is processed and answered.
    trace = Trace(duration=free / F_CPU + 0.12, serial=writes, encoders={})
    try:
        rec = record(trace, elf)
    except HarnessError:
        return None, cycles
    report = compare(rec)
    totals.runs += 1
    totals.events += report.events
    totals.ticks += report.ticks
    totals.fields += report.fields_compared
    totals.tx_bytes += report.tx_bytes
    totals.mismatches += len(report.mismatches)
    for m in report.mismatches[:3]:
        if len(totals.examples) < 10:
            totals.examples.append(f"run {totals.runs}: {m}")
    totals.extra_boots += rec.tx.count(b"BOOT:") - 1
    previous_tick = None
    for ev in rec.events:
        if ev.kind == "tick":
            if previous_tick is not None:
                totals.max_tick_gap_ms = max(totals.max_tick_gap_ms, (ev.arg - previous_tick) & 0xFFFFFFFF)
            previous_tick = ev.arg
    return rec, cycles


def _byte_effects(rec: Recording, cycles: list[int], totals: Lockstep) -> Iterator[tuple[int, Sram, Sram]]:
    """(byte index, SRAM before, SRAM after) for every processByte; books latencies."""
    from wcdrive.boards.simavr.virtual_mega import F_CPU

    previous = rec.initial
    k = 0
    for ev in rec.events:
        if ev.kind == "byte":
            if k < len(cycles):
                totals.max_latency_s = max(totals.max_latency_s, (ev.cycle - cycles[k]) / F_CPU)
            yield k, previous, ev.after
            k += 1
        previous = ev.after
    totals.lost_bytes += len(cycles) - k


def firmware_r1(n: int, rng: random.Random, elf: ElfPath, chunk: int | None = None
                ) -> dict[str, R1Slice]:
    """R1 on the firmware: chunks of ``chunk`` lines (default: 300, or a tenth of ``n``
    for small runs), four strict ones to a legacy one."""
    if chunk is None:
        chunk = max(20, min(300, n // 10))
    slices = {"strict": R1Slice(lockstep=Lockstep()), "legacy": R1Slice(lockstep=Lockstep())}
    index = 0
    while n > 0:
        count = min(chunk, n)
        n -= count
        strict = index % 5 != 4
        index += 1
        st = slices["strict" if strict else "legacy"]
        assert st.lockstep is not None
        lines = list(r1_lines(rng, count, strict))
        prefix = HELLO_FRAME if strict else b""
        line_of = [-1] * len(prefix)
        chunks = [(0.0, prefix)] if prefix else []
        for i, (_, line) in enumerate(lines):
            chunks.append((rng.uniform(0.0, 0.060) if rng.random() < 0.05 else 0.0, line))
            line_of.extend([i] * len(line))
        rec, cycles = _lockstep_run(chunks, elf, st.lockstep)
        if rec is None:
            st.crashes += 1
            st.lines.update(source for source, _ in lines)
            continue
        drove = [False] * count
        params = [False] * count
        sup0 = None
        for k, before, after in _byte_effects(rec, cycles, st.lockstep):
            i = line_of[k]
            if i < 0:
                continue
            if sup0 is None:
                sup0 = int(before["errSuppressed"])
            m1 = motion_in(after)
            arm = bool(after["cmdSinceTick"]) and not before["cmdSinceTick"]
            if not is_stop(m1) and (arm or m1 != motion_in(before)):
                drove[i] = True
            if any(before[f] != after[f] for f in _PARAM_FIELDS):
                params[i] = True
        end = rec.events[-1].after if rec.events else rec.initial
        st.suppressed += int(end["errSuppressed"]) - (sup0 or 0)
        kinds = answer_kinds(rec.tx)
        if strict:                                  # the hello's answer aside
            kinds.remove("HELLO")
            kinds.remove("ACK")
        for kind in kinds:
            st.answers["all", kind] += 1
        for i, (source, line) in enumerate(lines):
            # Only driving controls are checked here: a stop or a get/set may leave no
            # trace in SRAM when the state already matches; the port checks those.
            _check_line(st, source, line, strict, drove[i], False, params[i], None, False,
                        check=source in ("random", "mutated", "drive"))
    for st in slices.values():
        assert st.lockstep is not None
        st.worst_s = st.lockstep.max_latency_s
        st.hangs = (int(st.lockstep.max_latency_s > HANG_S) + int(st.lockstep.max_tick_gap_ms >= 2 * TICK_MS)
                    + st.lockstep.lost_bytes)
        st.crashes += st.lockstep.extra_boots
    return slices


# ---- R2 ----------------------------------------------------------------------------
def _executed(fw: Firmware, rest: Motion, params: tuple[float | int, ...]) -> bool:
    s = fw.state
    return (bool(s.cmdSinceTick) or motion_of(s) != rest or params_of(s) != params
            or bool(s.estopLatched))


def port_r2(n: int, rng: random.Random) -> R2Result:
    """R2 on the port: ``n`` corrupted motion frames after hello, a tick after each."""
    res = R2Result()
    board = _PortBoard(strict=True)
    rest, params = motion_of(board.fw.state), params_of(board.fw.state)
    clock = time.perf_counter
    for _ in range(n):
        kind, line = corrupt(rng, frame(cmdvel_command(rng), rng.randint(0, SEQ_MAX)))
        s = board.fw.state
        rejected0 = s.rejectedCount
        t0 = clock()
        try:
            out = board.fw.feed(line)
        except Exception as error:
            res.crashes += 1
            res.examples.append(f"crash on {line!r}: {error!r}")
            board = _PortBoard(strict=True)
            continue
        dt = clock() - t0
        res.worst_s = max(res.worst_s, dt)
        res.hangs += dt > HANG_S
        res.frames[kind] += 1
        kinds = answer_kinds(out)
        res.answers.update(kinds)
        acked = "ACK" in kinds
        executed = _executed(board.fw, rest, params)
        res.acked[kind] += acked
        res.executed[kind] += executed
        res.commands += len(split_commands(line))
        res.refused += s.rejectedCount - rejected0
        if (acked or executed) and len(res.examples) < 10:
            res.examples.append(f"{kind} {line!r}: {'ACKed ' if acked else ''}"
                                f"{'executed' if executed else ''}")
        if executed:
            board = _PortBoard(strict=True)
        else:
            board.tick()
    return res


def firmware_r2(n: int, rng: random.Random, elf: ElfPath, chunk: int = 500) -> R2Result:
    """R2 on the firmware: chunks of ``chunk`` corrupted frames after hello, at wire speed.
    Nothing may change the motion, the parameters or the e-stop, arm the watchdog or be
    ACKed (the hello's ACK aside), and every command must be refused."""
    totals = Lockstep()
    res = R2Result(lockstep=totals)
    while n > 0:
        count = min(chunk, n)
        n -= count
        lines = [corrupt(rng, frame(cmdvel_command(rng), rng.randint(0, SEQ_MAX)))
                 for _ in range(count)]
        data = b"".join(line for _, line in lines)
        rec, cycles = _lockstep_run([(0.0, HELLO_FRAME + data)], elf, totals)
        if rec is None:
            res.crashes += 1
            continue
        line_of = [-1] * len(HELLO_FRAME)
        for i, (_, line) in enumerate(lines):
            line_of.extend([i] * len(line))
        executed = [False] * count
        rejected0 = None
        fw_rest = params0 = None
        for k, before, after in _byte_effects(rec, cycles, totals):
            i = line_of[k]
            if i < 0:
                continue
            if rejected0 is None:
                rejected0 = int(before["rejectedCount"])
                fw_rest = motion_in(before)
                params0 = tuple(before[f] for f in _PARAM_FIELDS)
            if (after["cmdSinceTick"] or motion_in(after) != fw_rest or after["estopLatched"]
                    or tuple(after[f] for f in _PARAM_FIELDS) != params0):
                executed[i] = True
        end = rec.events[-1].after
        res.refused += int(end["rejectedCount"]) - (rejected0 or 0)
        kinds = answer_kinds(rec.tx)
        acks = kinds.count("ACK") - 1                        # the hello's
        res.answers.update(kinds)
        res.answers["ACK"] -= 1
        res.answers["HELLO"] -= 1
        for i, (kind, line) in enumerate(lines):
            res.frames[kind] += 1
            res.executed[kind] += executed[i]
            res.commands += len(split_commands(line))
            if executed[i] and len(res.examples) < 10:
                res.examples.append(f"{kind} {line!r}: executed")
        if acks:
            res.acked["any"] += acks
            res.examples.append(f"{acks} ACK lines in run {totals.runs}")
    res.worst_s = totals.max_latency_s
    res.hangs = int(totals.max_latency_s > HANG_S) + int(totals.max_tick_gap_ms >= 2 * TICK_MS) \
        + totals.lost_bytes
    res.crashes += totals.extra_boots
    return res


# ---- the legacy comparison: v1 lines before hello, and a model of v2 ---------------
def xor_checksum(data: bytes) -> int:
    value = 0
    for b in data:
        value ^= b
    return value


def v2_frame(command: bytes, seq: int) -> bytes:
    """A protocol v2 frame: ``$<seq>:<command>*<hh>\\n``, hh the XOR of the bytes between."""
    inner = b"%d:" % seq + command
    return b"$" + inner + b"*%02X\n" % xor_checksum(inner)


def _v2_hex(c: int) -> int:
    if 0x30 <= c <= 0x39:
        return c - 0x30
    if 0x41 <= c <= 0x46 or 0x61 <= c <= 0x66:
        return (c | 0x20) - 0x61 + 10
    return -1


def v2_unframe(buf: bytes) -> tuple[str | None, int, bytes]:
    """Protocol v2's ``unframe`` (git history, before v3): ``$[<seq>:]<command>*<hh>``
    with the XOR checksum in hex of either case, the seq optional."""
    n = len(buf)
    if n < 4 or buf[n - 3] != 0x2A:
        return "checksum", -1, buf
    hi, lo = _v2_hex(buf[n - 2]), _v2_hex(buf[n - 1])
    if hi < 0 or lo < 0 or xor_checksum(buf[1:n - 3]) != (hi << 4) | lo:
        return "checksum", -1, buf
    start, seq = 1, -1
    if 0x30 <= buf[1] <= 0x39:
        p = 1
        while 0x30 <= buf[p] <= 0x39:
            if p == 6:
                return "syntax", -1, buf
            p += 1
        if buf[p] != 0x3A or int(buf[1:p]) > SEQ_MAX:
            return "syntax", -1, buf
        seq, start = int(buf[1:p]), p + 1
    return None, seq, buf[start:n - 3]


def _outcome(fw: Firmware, intended: Motion) -> str:
    s = fw.state
    m = motion_of(s)
    if not s.cmdSinceTick and m == motion_of(FirmwareState()):
        return "refused"
    if m == intended:
        return "same"
    return "stop" if is_stop(m) else "different"


def legacy_rates(n: int, rng: random.Random) -> Legacy:
    """``n`` corrupted v1 lines and ``n`` corrupted v2 frames (model), each on a fresh
    board at rest that never said hello."""
    res = Legacy()
    for _ in range(n):
        cmd = cmdvel_command(rng)
        clean = Firmware()
        clean.feed(cmd + b"\n")
        intended = motion_of(clean.state)
        kind, line = corrupt(rng, cmd + b"\n")
        fw = Firmware()
        fw.feed(line)
        res.v1[kind, _outcome(fw, intended)] += 1
        res.frames[kind] += 1
    saved = commands.unframe
    commands.unframe = v2_unframe  # type: ignore[assignment]   # the model: v3's port, v2's frame check
    try:
        for _ in range(n):
            cmd = cmdvel_command(rng)
            clean = Firmware()
            clean.feed(cmd + b"\n")
            intended = motion_of(clean.state)
            kind, line = corrupt(rng, v2_frame(cmd, rng.randint(0, SEQ_MAX)))
            fw = Firmware()
            out = fw.feed(line)
            outcome = _outcome(fw, intended)
            res.v2[kind, outcome] += 1
            res.frames_v2[kind] += 1
            if outcome == "different" and b"ACK:" in out:
                res.v2_acked_different[kind] += 1
    finally:
        commands.unframe = saved
    return res


# ---- R3: link cut, unplug and DTR reset mid-motion (the firmware in simavr, live) -----
R3_KINDS = ("link cut", "unplug", "DTR reset")
WHEEL_RADIUS = real("WHEEL_RADIUS")
WATCHDOG_S = integer("WATCHDOG_MS") / 1000
EMERGENCY_DECEL = real("EMERGENCY_DECEL")
PERIOD_S = integer("CONTROL_PERIOD_MS") / 1000
HOST_PERIOD_S = 0.05            # the host's motion commands: 20 Hz
STANDSTILL_MPS = 0.01
RECOVERY_TIMEOUT_S = 5.0
_ACK = re.compile(rb"ACK:(\d+)\r\n")
_BOOT = re.compile(rb"BOOT:[^,\r\n]*,([A-Z_]+)\r\n")

Sample = tuple[int, int, int, float, float, float]      # cycle, PWM left, right, speed, x, y


def stop_bound(speed: float, watchdog: bool = True) -> float:
    """The longest it may take, from the moment the board last heard the host (or
    reset), until PWM is 0 for good at ``speed`` m/s: the watchdog and its latency of
    up to two ticks (not after a reset), braking from the wheels' speed at the gentler
    of the emergency deceleration and the hardest the motors brake
    (``ChairParams.max_braking``: docs/safety.md), and two control ticks (the one that
    sees the wheels slow enough, the one that parks)."""
    return ((WATCHDOG_S + 2 * PERIOD_S if watchdog else 0.0) + speed / _braking() + 2 * PERIOD_S)


def _braking() -> float:
    """m/s^2: the braking the stop can achieve (docs/safety.md)."""
    from wcdrive.plant import ChairParams

    return min(EMERGENCY_DECEL * WHEEL_RADIUS, ChairParams().max_braking)


def travel_bound(speed: float, watchdog: bool = True) -> float:
    """Issue 13's goal for the distance after the last byte: constant speed over the
    watchdog time (not after a reset), the braking distance at the emergency
    deceleration, plus 0.1 m."""
    return ((speed * (WATCHDOG_S + 2 * PERIOD_S) if watchdog else 0.0) + speed * speed / (2 * _braking())
            + 0.1)


class FaultyLink:
    """The USB cable between a host and a live ``MegaBoard``, a ``Port``, with faults.
    ``cut()``: the bytes are lost both ways while the port stays open (the write under
    way when it happens is cut after a random number of its bytes); ``restore()``.
    ``unplug()``: the device vanishes (reads, writes and reopening raise
    ``SerialException``, as pyserial's do) until ``replug()``. Opening the port again
    (``reopen``) pulses DTR, which resets the board, as on a real Mega. Every byte the
    board sends is kept in ``board_tx``, delivered or not; ``delivered``: those the
    host got."""

    def __init__(self, board: MegaBoard, rng: random.Random, timeout: float = 0.05) -> None:
        from wcdrive.boards.receive_buffer import ReceiveBuffer

        self.board = board
        self.timeout: float | None = timeout
        self.board_tx = bytearray()
        self.delivered = bytearray()
        self.state = "up"                       # up | cut | gone
        self.is_open = True
        self._rng = rng
        self._cut_pending = False
        self._rx = ReceiveBuffer()
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._pump = threading.Thread(target=self._pump_loop, name="r3-link", daemon=True)
        self._pump.start()

    def _pump_loop(self) -> None:
        while not self._done.is_set():
            data = self.board.read(4096, timeout=0.01)
            if not data:
                continue
            with self._lock:
                self.board_tx += data
                if self.state == "up" and self.is_open:
                    self.delivered += data
                    self._rx.put(data)

    def _check(self) -> None:
        import serial

        if self.state == "gone":
            raise serial.SerialException("device reports readiness to read but returned no data "
                                         "(device disconnected or multiple access on port?)")
        if not self.is_open:
            raise serial.PortNotOpenError()

    # ---- the Port ------------------------------------------------------------------
    @property
    def in_waiting(self) -> int:
        """Bytes delivered and not read yet."""
        self._check()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting at most ``timeout`` s for the first."""
        self._check()
        data = self._rx.read(size, self.timeout)
        if not data:
            self._check()                       # unplugged while waiting
        return data

    def write(self, data: bytes) -> int:
        """Hands ``data`` to the board, unless the link is cut."""
        self._check()
        with self._lock:
            state, cut_now = self.state, self._cut_pending
            self._cut_pending = False
        if state == "up":
            self.board.write(data)
        elif cut_now and len(data) > 1:         # cut in the middle of this line
            self.board.write(data[:self._rng.randrange(1, len(data))])
        return len(data)

    def flush(self) -> None:
        """Nothing to wait for."""
        self._check()

    def close(self) -> None:
        """Closes the port (the board runs on)."""
        self.is_open = False
        self._rx.clear()

    def reopen(self) -> FaultyLink:
        """Opens the port again (``Session``'s reopen): raises while unplugged; else
        pulses DTR, which resets the board."""
        import serial

        if self.state == "gone":
            raise serial.SerialException("[Errno 2] could not open port: No such file or directory")
        self._rx.clear()
        self.is_open = True
        self.board.reset("external")
        return self

    # ---- faults --------------------------------------------------------------------
    def cut(self) -> None:
        """Loses the bytes both ways from now on (the next write is cut after some bytes)."""
        with self._lock:
            self.state = "cut"
            self._cut_pending = True

    def restore(self) -> None:
        """Ends a cut."""
        with self._lock:
            self.state = "up"
            self._cut_pending = False

    def unplug(self) -> None:
        """The device vanishes."""
        with self._lock:
            self.state = "gone"
            self._rx.clear()

    def replug(self) -> None:
        """The device is back; the host must open it again."""
        with self._lock:
            self.state = "up"

    def shutdown(self) -> None:
        """Stops the pump (the board is closed by its owner)."""
        self._done.set()
        self._pump.join(timeout=1.0)


@dataclass
class R3Trial:
    """One fault mid-motion. Board times are simulated seconds from the fault, host
    times wall seconds from the fault (``recovered_s``: from the end of the outage, or
    from the reset); None: never (within the trial)."""

    kind: str
    speed: float                        # commanded, m/s
    bound_s: float                      # stop_bound(speed), no watchdog for a reset
    travel_bound_m: float               # travel_bound(speed), likewise
    pwm_before: tuple[int, int] = (0, 0)
    pwm_after: tuple[int, int] = (0, 0)  # right after the fault (a reset: its first instruction)
    pwm_zero_s: float | None = None     # both PWM 0 for good (to the end of the outage)
    standstill_s: float | None = None   # the chair's speed below 0.01 m/s for good
    travel_m: float = 0.0
    noticed_s: float | None = None      # the host: LinkLost, a refused motion call, or BOARD_RESET
    noticed_by: str = ""
    recovered_s: float | None = None    # the host drives again (after a reset or a replug: hello again)
    rehandshake: bool = False           # hello answered again after the fault
    boot_cause: str = ""                # as the host reported it (BOARD_RESET,<cause>), or its BOOT line
    executed_before_hello: int = 0      # frames the board executed after its reset, before a new hello
    link_losses_before: int = 0         # LinkLost while driving, before the fault (the board lagged)

    def stopped_in_time(self) -> bool:
        """PWM 0 for good within the bound; after a reset, PWM 0 from its first
        instruction (issue 14: "PWM reaches 0"). The fresh firmware then finds the chair
        still rolling and brakes it under its PID, setpoint 0, until it has been still
        for 3 ticks: ``pwm_zero_s`` reports that, and it is not a drive."""
        if self.kind == "DTR reset":
            return self.pwm_after == (0, 0)
        return self.pwm_zero_s is not None and self.pwm_zero_s <= self.bound_s


@dataclass
class R3Result:
    """R3: the trials of each kind, the frames the board executed (ACKed) and those
    executed twice, and how well the board kept to real time."""

    trials: dict[str, list[R3Trial]] = field(default_factory=dict)
    acked: int = 0
    executed_twice: list[int] = field(default_factory=list)
    board_lag_s: float = 0.0            # the most simulated time fell behind the (paced) wall clock
    pace: float = 1.0                   # simulated seconds per wall second
    examples: list[str] = field(default_factory=list)


class _Probe:
    """``MegaBoard.on_step``: a ``Sample`` at each step, since when the chair has been
    still and unpowered, and how far simulated time fell behind the wall clock."""

    def __init__(self, board: MegaBoard) -> None:
        self.board = board
        self.samples: list[Sample] = []
        self.cycle = 0
        self.quiet_since: int | None = None
        self.wall0: float | None = None
        self.lag = 0.0

    def __call__(self, tx: list[tuple[int, int]]) -> None:
        from wcdrive.avr.timer0 import F_CPU

        mega, plant = self.board.mega, self.board.plant
        assert plant is not None
        forward, lateral = plant.axle_velocity()
        x, y, _ = plant.pose
        sample = (mega.cycle, mega.pwm("left"), mega.pwm("right"), math.hypot(forward, lateral), x, y)
        self.samples.append(sample)
        self.cycle = sample[0]
        if sample[1] == 0 and sample[2] == 0 and sample[3] < STANDSTILL_MPS:
            if self.quiet_since is None:
                self.quiet_since = sample[0]
        else:
            self.quiet_since = None
        now = time.monotonic() * self.board.speed
        if self.wall0 is None:
            self.wall0 = now - sample[0] / F_CPU
        self.lag = max(self.lag, now - self.wall0 - sample[0] / F_CPU)

    def quiet_for(self) -> float:
        """Simulated seconds for which PWM has been 0 and the chair still."""
        from wcdrive.avr.timer0 import F_CPU

        since = self.quiet_since
        return 0.0 if since is None else (self.cycle - since) / F_CPU


def analyse_stop(samples: list[Sample], fault_cycle: int, end_cycle: int
                 ) -> tuple[float | None, float | None, float]:
    """From the probe's samples between the fault and the end of the outage: PWM 0 for
    good and standstill for good, each in s after the fault (None: not by the end),
    and the distance the chair travelled."""
    from wcdrive.avr.timer0 import F_CPU

    pwm_zero: float | None = 0.0
    still: float | None = 0.0
    travel = 0.0
    previous: tuple[float, float] | None = None
    seen = False
    for cycle, left, right, speed, x, y in samples:
        if not fault_cycle <= cycle <= end_cycle:
            continue
        seen = True
        t = (cycle - fault_cycle) / F_CPU
        if left or right:
            pwm_zero = None
        elif pwm_zero is None:
            pwm_zero = t
        if speed >= STANDSTILL_MPS:
            still = None
        elif still is None:
            still = t
        if previous is not None:
            travel += math.hypot(x - previous[0], y - previous[1])
        previous = (x, y)
    if not seen:
        return None, None, 0.0
    return pwm_zero, still, travel


def executed_before_hello(board_tx: bytes) -> int:
    """Frames a board executed (``ACK:``) after its ``BOOT:`` line and before it answered
    a new hello (the ACK of the hello itself aside): what it took while lax, with the
    host unaware of the reset."""
    boot = board_tx.find(b"BOOT:")
    if boot < 0:
        return 0
    after = board_tx[boot:]
    hello = after.find(b"HELLO:")
    return len(_ACK.findall(after if hello < 0 else after[:hello]))


class _Rig:
    """The firmware in simavr with the chair on its pins, at real time (times ``pace``),
    behind a ``FaultyLink``, driven by a ``Wheelchair`` as a program would, whose
    link timeout is stretched by 1 / ``pace`` too."""

    def __init__(self, elf: ElfPath, rng: random.Random, pace: float = 1.0) -> None:
        from wcdrive.boards.simavr.mega_board import MegaBoard
        from wcdrive.host.wheelchair import LINK_TIMEOUT, Wheelchair

        self.pace = pace
        self.board = MegaBoard(elf, realtime=True, speed=pace)
        self.probe = _Probe(self.board)
        self.board.on_step = self.probe
        self.board.start()
        self.link = FaultyLink(self.board, rng)
        self.link_events: list[tuple[float, object]] = []
        self.errors: list[str] = []
        self.chair = Wheelchair(self.link, name="wcavr-r3", reopen=self.link.reopen,
                                reconnect_timeout=30.0, stop_on_signals=False,
                                link_timeout=LINK_TIMEOUT / pace)
        self.chair.on_link(lambda event: self.link_events.append((time.monotonic(), event)))
        self.chair.wait_for_handshake(10.0)

    def close(self) -> None:
        try:
            self.chair.close()
        finally:
            self.link.shutdown()
            self.board.close()


def _r3_trial(rig: _Rig, kind: str, rng: random.Random) -> R3Trial:
    """Drives at a random speed for 0.6-1.0 s, then the fault at a random moment
    between two commands; the host keeps commanding until it notices, then waits until
    the chair has stopped; then the link comes back (replugged: a DTR reset on open)
    and the host must drive again."""
    from wcdrive.errors import WcdriveError
    from wcdrive.host.telemetry import LinkLost

    chair, link, board = rig.chair, rig.link, rig.board
    period, stretch = HOST_PERIOD_S / rig.pace, 1.0 / rig.pace      # in wall seconds
    speed = rng.uniform(0.4, 1.2)
    watchdog = kind != "DTR reset"
    trial = R3Trial(kind, speed, stop_bound(speed, watchdog), travel_bound(speed, watchdog))
    links_start = len(rig.link_events)
    t_stop = time.monotonic() + rng.uniform(0.6, 1.0) * stretch
    while True:
        t_last = time.monotonic()
        try:
            chair.set_velocity(speed, 0.0)
        except WcdriveError as exc:
            rig.errors.append(f"{kind}: a motion call before the fault failed: {exc}")
        if t_last + period >= t_stop:
            break
        time.sleep(max(0.0, t_last + period - time.monotonic()))
    time.sleep(max(0.0, t_last + rng.uniform(0.0, period) - time.monotonic()))
    events0, links0, errors0 = len(chair.events), len(rig.link_events), len(chair.errors)
    hellos0, delivered0, tx0 = link.delivered.count(b"HELLO:"), len(link.delivered), len(link.board_tx)
    trial.link_losses_before = sum(isinstance(e, LinkLost) for _, e in rig.link_events[links_start:links0])

    def fault(mega: VirtualMega) -> tuple[int, tuple[int, int], tuple[int, int]]:
        before = (mega.pwm("left"), mega.pwm("right"))
        if kind == "link cut":
            link.cut()
        elif kind == "unplug":
            link.unplug()
        else:
            mega.reset("external")
        return mega.cycle, before, (mega.pwm("left"), mega.pwm("right"))

    def ready() -> bool:
        hello_again = link.delivered.count(b"HELLO:") > hellos0
        trial.rehandshake = hello_again
        return (chair.link_ok and chair.protocol_version == 3
                and (kind == "link cut" or hello_again))

    t_fault = time.monotonic()
    fault_cycle, trial.pwm_before, trial.pwm_after = board.between_steps(fault)
    # The host: a command every 50 ms until it notices (a refused call, LinkLost,
    # BOARD_RESET), then none. The outage lasts until the chair has been still and
    # unpowered for 0.1 s (at least 0.3 s, at most 2.5 s past the stop bound).
    next_command = t_last + period
    min_end, max_end = t_fault + 0.3 * stretch, t_fault + (stop_bound(speed) + 2.5) * stretch
    while time.monotonic() < max_end:
        now = time.monotonic()
        if trial.noticed_s is None:
            lost = [t for t, e in rig.link_events[links0:] if isinstance(e, LinkLost)]
            resets = [e for e in chair.events[events0:] if e.startswith("BOARD_RESET")]
            if lost:
                trial.noticed_s, trial.noticed_by = (lost[0] - t_fault) * rig.pace, "LinkLost"
            elif resets:
                trial.noticed_s, trial.noticed_by = (now - t_fault) * rig.pace, "BOOT"
                trial.boot_cause = resets[0].partition(",")[2]
            elif now >= next_command:
                next_command += period
                try:
                    chair.set_velocity(speed, 0.0)
                except WcdriveError:
                    trial.noticed_s, trial.noticed_by = (now - t_fault) * rig.pace, "refused"
        elif now >= min_end and rig.probe.quiet_for() >= 0.1:
            break
        if kind == "DTR reset" and trial.recovered_s is None and ready():
            trial.recovered_s = (now - t_fault) * rig.pace
        time.sleep(0.005)
    end_cycle = board.between_steps(lambda mega: mega.cycle)
    if kind == "link cut":
        link.restore()
    elif kind == "unplug":
        link.replug()
    t_back = time.monotonic()
    deadline = t_back + RECOVERY_TIMEOUT_S * stretch
    while time.monotonic() < deadline:
        if ready():
            try:
                chair.set_velocity(0.0, 0.0)
            except WcdriveError:
                pass
            else:
                if trial.recovered_s is None and kind != "DTR reset":
                    trial.recovered_s = (time.monotonic() - t_back) * rig.pace
                break
        time.sleep(0.005)
    else:
        trial.recovered_s = None
    got = bytes(link.delivered[delivered0:])
    boots = _BOOT.findall(got)
    if not trial.boot_cause and boots:          # a replug: its BOOT line came before hello
        trial.boot_cause = boots[0].decode()
    if kind == "DTR reset" and trial.noticed_s is None and boots:
        whole = bytes(link.delivered)               # the line may have begun before the fault
        at = whole.find(b"BOOT:", delivered0)
        line = whole[whole.rfind(b"\n", 0, at) + 1:whole.find(b"\n", at) + 1]
        rig.errors.append(f"{kind}: the host got {line!r} and did not see the reset")
    elif kind != "link cut" and trial.noticed_s is not None and not trial.rehandshake:
        rig.errors.append(f"{kind}: the host saw the reset and said hello, but got "
                          f"{['ERR:' + e for e in chair.errors[errors0:]]} and no HELLO; "
                          f"protocol_version {chair.protocol_version}")
    trial.executed_before_hello = executed_before_hello(bytes(link.board_tx[tx0:]))
    trial.pwm_zero_s, trial.standstill_s, trial.travel_m = analyse_stop(rig.probe.samples,
                                                                        fault_cycle, end_cycle)
    del rig.probe.samples[:-1]
    return trial


def firmware_r3(trials: int, rng: random.Random, elf: ElfPath, log: bool = False,
                pace: float = 1.0) -> R3Result:
    """R3: ``trials`` of each kind (link cut, unplug, DTR reset), mixed in a random
    order, on one live board at real time behind a ``FaultyLink``, driven by a
    ``Wheelchair``. Each time the chair must stop (PWM 0 within ``stop_bound``; after
    a reset also at its first instruction), the host must notice and drive again
    (after a reset or a replug: after a new hello), and no frame is executed twice.
    ``pace`` < 1 runs the board slower than real time, and the host's clock with it
    (its command period and link timeout), for a loaded machine: host times are
    reported in the board's seconds."""
    res = R3Result(trials={k: [] for k in R3_KINDS}, pace=pace)
    order = [k for k in R3_KINDS for _ in range(trials)]
    rng.shuffle(order)
    acks: Counter[int] = Counter()

    def finish(rig: _Rig) -> None:
        rig.close()
        acks.update(int(s) for s in _ACK.findall(bytes(rig.link.board_tx)))
        res.acked += sum(acks.values())
        res.executed_twice += sorted(s for s, n in acks.items() if n > 1)
        res.board_lag_s = max(res.board_lag_s, rig.probe.lag)
        res.examples.extend(rig.errors)
        acks.clear()

    rig = _Rig(elf, rng, pace)
    try:
        for i, kind in enumerate(order):
            trial = _r3_trial(rig, kind, rng)
            res.trials[kind].append(trial)
            if log and (i + 1) % 30 == 0:
                print(f"    R3 {i + 1}/{len(order)}", file=sys.stderr, flush=True)
            if trial.recovered_s is None:           # a host that never came back: start again
                res.examples.append(f"trial {i + 1} ({kind}): the host never drove again; "
                                    "a new board and host for the next")
                finish(rig)
                rig = _Rig(elf, rng, pace)
    finally:
        finish(rig)
    return res


def r3_problems(r: R3Result) -> list[str]:
    """What R3 found wrong, by kind (empty: every trial as required)."""
    found = []
    for kind, trials in r.trials.items():
        bad = {
            "trials not in motion at the fault": sum(t.pwm_before == (0, 0) for t in trials),
            "stops late or never (PWM)": sum(not t.stopped_in_time() for t in trials),
            "faults the host did not notice": sum(t.noticed_s is None for t in trials),
            "hosts that never drove again": sum(t.recovered_s is None for t in trials),
        }
        if kind != "link cut":
            bad["re-handshakes missing"] = sum(not t.rehandshake for t in trials)
            bad["reboots without the cause EXTERNAL"] = sum(t.boot_cause != "EXTERNAL" for t in trials)
        found += [f"R3 {kind}: {v} {k}" for k, v in bad.items() if v]
    if r.executed_twice:
        found.append(f"R3: sequence numbers executed twice: {r.executed_twice[:10]}")
    return found + [f"  {e}" for e in r.examples[:10]]


def _stats(values: list[float], unit: str, scale: float = 1.0, digits: int = 0) -> str:
    if not values:
        return "-"
    values = sorted(v * scale for v in values)
    median = values[len(values) // 2]
    return f"{median:.{digits}f} / {values[-1]:.{digits}f} {unit}"


def _r3_cell(r: R3Result | None) -> str:
    if r is None:
        return "not run"
    parts = []
    for kind, trials in r.trials.items():
        n = len(trials)
        parts.append(f"{kind}: {n - sum(not t.stopped_in_time() for t in trials)}/{n} stopped in time, "
                     f"{sum(t.noticed_s is not None for t in trials)}/{n} noticed, "
                     f"{sum(t.recovered_s is not None for t in trials)}/{n} driving again"
                     + ("" if kind == "link cut" else
                        f" ({sum(t.rehandshake for t in trials)}/{n} after a new hello)"))
    return "; ".join(parts) + (f"; **{len(r.executed_twice)} of {_n(r.acked)} executed frames "
                               "executed twice**")


def r3_table(r: R3Result | None) -> list[str]:
    """R3's figures by kind, as markdown lines."""
    if r is None:
        return []
    paced = "at real time" if r.pace == 1.0 else f"at {r.pace:g}x real time (the host's clock alike)"
    out = [f"R3 on the firmware in simavr with the chair on its pins, {paced}, driven by a "
           "`Wheelchair` at 20 Hz at 0.4-1.2 m/s (median / max, in ms of the board's clock "
           "from the fault; the host's times are wall times times the pace; driving again: "
           "from the end of the outage, or from the reset):", "",
           "| fault | trials | PWM 0 for good | standstill | travel (within issue 13's "
           "bound) | host notices (by) | driving again | reboot cause the host saw | frames the "
           "board executed after its reset before a new hello |",
           "|---|---:|---|---|---|---|---|---|---:|"]
    for kind, trials in r.trials.items():
        by = Counter(t.noticed_by or "not noticed" for t in trials)
        causes = Counter(t.boot_cause or "none" for t in trials)
        zero = [t.pwm_zero_s for t in trials if t.pwm_zero_s is not None]
        over = [t.pwm_zero_s - t.bound_s for t in trials if t.pwm_zero_s is not None]
        late = sum(t.pwm_zero_s is None for t in trials)
        within = sum(t.travel_m <= t.travel_bound_m for t in trials)
        first = (f"; PWM 0 at the reset's first instruction {sum(t.pwm_after == (0, 0) for t in trials)}"
                 f"/{len(trials)}" if kind == "DTR reset" else "")
        out.append(
            f"| {kind} | {len(trials)} | {_stats(zero, 'ms', 1e3)}"
            + (f", not by the end {late}" if late else "")
            + f" (bound {_stats([t.bound_s for t in trials], 'ms', 1e3)}; past it by "
            f"{_stats(over, 'ms', 1e3)}){first} | "
            f"{_stats([t.standstill_s for t in trials if t.standstill_s is not None], 'ms', 1e3)} | "
            f"{_stats([t.travel_m for t in trials], 'm', 1.0, 3)} ({within}/{len(trials)}) | "
            f"{_stats([t.noticed_s for t in trials if t.noticed_s is not None], 'ms', 1e3)} "
            f"({', '.join(f'{k} {v}' for k, v in by.items())}) | "
            f"{_stats([t.recovered_s for t in trials if t.recovered_s is not None], 'ms', 1e3)} | "
            f"{', '.join(f'{k} {v}' for k, v in causes.items())} | "
            f"{sum(t.executed_before_hello for t in trials)} in "
            f"{sum(t.executed_before_hello > 0 for t in trials)} trials |")
    losses = sum(t.link_losses_before for ts in r.trials.values() for t in ts)
    out += ["", f"Frames the board executed (ACKed): {_n(r.acked)}; executed twice: "
            f"{len(r.executed_twice)}. Link losses while driving, before a fault: {losses}; the "
            f"board fell at most {r.board_lag_s * 1e3:.0f} ms behind the wall clock."]
    return out


# ---- the whole run -----------------------------------------------------------------
def run(counts: dict[str, int], seed: int = 1, simavr: bool = True, elf: ElfPath = None,
        log: bool = False, r3_pace: float = 1.0) -> Results:
    """Every test with these counts (keys of ``FULL``); R3's board runs at ``r3_pace``
    times real time."""
    res = Results(seed, dict(counts))

    def timed(name: str, fn, *args):
        t0 = time.perf_counter()
        value = fn(*args)
        res.wall[name] = time.perf_counter() - t0
        if log:
            print(f"  {name}: {res.wall[name]:.1f} s", file=sys.stderr, flush=True)
        return value

    lines = counts["port_lines"]
    legacy_lines = lines // 5
    res.r1_port["strict"] = timed("R1 port, strict", port_r1, lines - legacy_lines,
                                  random.Random(seed * 1000 + 1), True)
    res.r1_port["legacy"] = timed("R1 port, legacy", port_r1, legacy_lines,
                                  random.Random(seed * 1000 + 2), False)
    res.r2_port = timed("R2 port", port_r2, counts["port_frames"], random.Random(seed * 1000 + 3))
    res.legacy = timed("v1/v2 comparison", legacy_rates, counts["legacy_frames"],
                       random.Random(seed * 1000 + 4))
    if simavr:
        if elf is None:
            from wcdrive.boards.simavr.build import firmware_elf

            elf = firmware_elf()
        res.r1_firmware = timed("R1 firmware", firmware_r1, counts["firmware_lines"],
                                random.Random(seed * 1000 + 5), elf)
        res.r2_firmware = timed("R2 firmware", firmware_r2, counts["firmware_frames"],
                                random.Random(seed * 1000 + 6), elf)
        if counts.get("r3_trials", 0) > 0:
            res.r3 = timed("R3 firmware", firmware_r3, counts["r3_trials"],
                           random.Random(seed * 1000 + 7), elf, log, r3_pace)
    return res


# ---- report --------------------------------------------------------------------------
def _n(x: int) -> str:
    return f"{x:,}"


def _pct(a: int, b: int) -> str:
    if b == 0:
        return "-"
    p = 100.0 * a / b
    return "0" if a == 0 else f"{p:.3g} %"


def _r1_cell(slices: dict[str, R1Slice], firmware: bool) -> str:
    if not slices:
        return "not run"
    s, g = slices["strict"], slices["legacy"]
    total = s.total + g.total
    crashes = s.crashes + g.crashes
    hangs = s.hangs + g.hangs
    invalid = s.invalid + g.invalid
    motions = s.invalid_motions + g.invalid_motions
    params = s.invalid_param_changes + g.invalid_param_changes
    drives = s.controls["drive"] + g.controls["drive"]
    drives_ok = s.controls_ok["drive"] + g.controls_ok["drive"]
    worst = max(s.worst_s, g.worst_s) * 1e3
    if firmware:
        ls = [x.lockstep for x in (s, g) if x.lockstep]
        slowest = (f"a byte waits at most {worst:.2f} ms for processByte, "
                   f"{sum(x.lost_bytes for x in ls)} bytes lost, ticks at most "
                   f"{max(x.max_tick_gap_ms for x in ls)} ms apart")
    else:
        slowest = f"slowest line {worst:.2f} ms"
    text = (f"{_n(total)} lines ({_n(s.total)} after hello, {_n(g.total)} before): "
            f"**{crashes} crashes, {hangs} hangs** ({slowest}), "
            f"**{motions} motions** and {params} parameter changes from "
            f"{_n(invalid)} invalid lines; valid motions carried out {_n(drives_ok)}/{_n(drives)}")
    if firmware:
        mism = sum(x.mismatches for x in ls)
        text += (f"; **port = firmware: {mism} mismatches** in {_n(sum(x.events for x in ls))} "
                 f"events ({_n(sum(x.ticks for x in ls))} ticks, {_n(sum(x.fields for x in ls))} "
                 f"values and TX streams of {_n(sum(x.tx_bytes for x in ls))} bytes compared), "
                 f"{sum(x.runs for x in ls)} boots")
    return text


def _r2_cell(r: R2Result | None) -> str:
    if r is None:
        return "not run"
    frames = sum(r.frames.values())
    text = (f"{_n(frames)} frames: **{sum(r.executed.values())} executed, "
            f"{sum(r.acked.values())} ACKed**, {r.crashes} crashes, {r.hangs} hangs; "
            f"{_n(r.refused)} of the {_n(r.commands)} commands they make refused")
    if r.lockstep is not None:
        ls = r.lockstep
        text += (f" (a byte waits at most {ls.max_latency_s * 1e3:.2f} ms, {ls.lost_bytes} lost); "
                 f"**port = firmware: {ls.mismatches} mismatches** in {_n(ls.events)} events "
                 f"({_n(ls.fields)} values compared), {ls.runs} boots")
    return text


def markdown(res: Results) -> str:
    """The tables, ready to paste."""
    out = [f"Seed {res.seed}; counts {res.counts}.", ""]
    out += ["| test | on the port | on the firmware (simavr, lock step) |", "|---|---|---|"]
    out.append("| R1: random and mutated lines, 0 crashes, 0 hangs, 0 motions from invalid input, "
               f"port = firmware | {_r1_cell(res.r1_port, False)} | "
               f"{_r1_cell(res.r1_firmware, True)} |")
    out.append("| R2: 1- to 3-bit flips and bursts of 2 to 16 bits in valid motion frames, the `$` "
               f"included, after hello: 0 executed, 0 ACKed | {_r2_cell(res.r2_port)} | "
               f"{_r2_cell(res.r2_firmware)} |")
    out.append("| R3: the link cut, the board unplugged and a DTR reset, each mid-motion: the "
               "chair stops within the watchdog bound (a reset: PWM 0 from its first "
               "instruction), the host notices and re-handshakes, no frame executed twice | - | "
               f"{_r3_cell(res.r3)} |")
    out += ["", *_r1_details(res), "", *r3_table(res.r3), "", *_reply_table(res), "",
            *_comparison_table(res), ""]
    total = sum(res.wall.values())
    out.append("Wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in res.wall.items())
               + f"; total {total:.1f} s.")
    return "\n".join(out)


def _r1_details(res: Results) -> list[str]:
    out = ["| R1 slice | lines (random / mutated / valid) | invalid (oracle) | motions from invalid "
           "| mutations that are valid input (of which drove) | valid drive / stop / get-set carried out |",
           "|---|---|---|---|---|---|"]
    for side, slices in (("port", res.r1_port), ("firmware", res.r1_firmware)):
        for name, st in slices.items():
            valid = st.total - st.lines["random"] - st.lines["mutated"]
            ok = " / ".join(f"{_n(st.controls_ok[k])}/{_n(st.controls[k])}"
                            for k in ("drive", "stop", "param") if st.controls[k])
            out.append(f"| {side}, {'after hello' if name == 'strict' else 'before hello (legacy)'} | "
                       f"{_n(st.lines['random'])} / {_n(st.lines['mutated'])} / {_n(valid)} | "
                       f"{_n(st.invalid)} | {st.invalid_motions} | {_n(st.mutated_valid)} "
                       f"({_n(st.mutated_valid_drove)}) | {ok} |")
    return out


def _reply_table(res: Results) -> list[str]:
    """R1 answers per 100 lines on the port, by source, and the firmware's totals."""
    cols: list[tuple[str, R1Slice, str]] = []
    for name, st in res.r1_port.items():
        tag = "after hello" if name == "strict" else "before hello"
        for group in ("random", "mutated", "valid"):
            cols.append((f"{group}, {tag}", st, group))
    kinds = sorted({k for _, st, _ in cols for (_, k) in st.answers})
    out = ["R1 answers per 100 lines on the port (a tick after every line; a line that makes "
           "more than 3 commands loses the answers past the third):", "",
           "| answer | " + " | ".join(c[0] for c in cols) + " |",
           "|---|" + "---:|" * len(cols)]

    def lines_in(st: R1Slice, group: str) -> int:
        if group == "valid":
            return st.total - st.lines["random"] - st.lines["mutated"]
        return st.lines[group]

    for kind in [*kinds, "(no answer)"]:
        cells = []
        for _, st, group in cols:
            count = st.silent[group] if kind == "(no answer)" else st.answers[group, kind]
            total = lines_in(st, group)
            cells.append(f"{100.0 * count / total:.2f}" if total else "-")
        out.append(f"| {kind} | " + " | ".join(cells) + " |")
    out += ["", "Answers suppressed by the 3-per-tick budget on the port: " + ", ".join(
        f"{'after hello' if name == 'strict' else 'before hello'} {_n(st.suppressed)}"
        for name, st in res.r1_port.items()) + "."]
    if res.r1_firmware:
        out += ["", "On the firmware, at wire speed (3 answers per 50 ms tick, the rest suppressed): "
                + "; ".join(
                    f"{'after hello' if name == 'strict' else 'before hello'}: {_n(st.total)} lines, "
                    + ", ".join(f"{k} {_n(v)}" for (_, k), v in sorted(st.answers.items()))
                    + f", suppressed {_n(st.suppressed)}"
                    for name, st in res.r1_firmware.items()) + "."]
    return out


def _comparison_table(res: Results) -> list[str]:
    r2, lg = res.r2_port, res.legacy
    if r2 is None or lg is None:
        return []
    out = ["Corrupted motion commands by kind of corruption: v3 frames after hello (R2, port) "
           "against the bare v1 line before hello and a model of v2's XOR frames:", "",
           "| corruption | v3: executed / ACKed | v1 line before hello: different motion / "
           "same motion / refused | v2 model (XOR): different motion / same / refused |",
           "|---|---|---|---|"]

    def row(name: str, kinds: tuple[str, ...]) -> str:
        frames = sum(r2.frames[k] for k in kinds)
        n1 = sum(lg.frames[k] for k in kinds)
        n2 = sum(lg.frames_v2[k] for k in kinds)

        def rates(table: Counter[tuple[str, str]], n: int) -> str:
            return " / ".join(_pct(sum(table[k, outcome] for k in kinds), n)
                              for outcome in ("different", "same", "refused")) + f" of {_n(n)}"

        return (f"| {name} | {sum(r2.executed[k] for k in kinds)} / {sum(r2.acked[k] for k in kinds)}"
                f" of {_n(frames)} | {rates(lg.v1, n1)} | {rates(lg.v2, n2)} |")

    for kind in CORRUPTIONS:
        out.append(row(kind, (kind,)))
    out.append(row("all", CORRUPTIONS))
    stops = sum(v for (_, o), v in lg.v1.items() if o == "stop")
    stops2 = sum(v for (_, o), v in lg.v2.items() if o == "stop")
    out += ["", f"(Corruptions that turned the command into a stop: v1 {_n(stops)}, v2 model "
            f"{_n(stops2)}; v2 model frames ACKed while executing a different motion: "
            f"{_n(sum(lg.v2_acked_different.values()))}.)"]
    return out


def problems(res: Results) -> list[str]:
    """What the run found wrong (empty: every figure is as required)."""
    found = []
    for side, slices in (("port", res.r1_port), ("firmware", res.r1_firmware)):
        for name, st in slices.items():
            bad = {"crashes": st.crashes, "hangs": st.hangs, "motions from invalid input":
                   st.invalid_motions, "parameter changes from invalid input":
                   st.invalid_param_changes,
                   "valid motions not carried out": st.controls["drive"] - st.controls_ok["drive"]}
            if side == "port":
                bad["valid stops/params not carried out"] = (
                    st.controls["stop"] + st.controls["param"]
                    - st.controls_ok["stop"] - st.controls_ok["param"])
            if st.lockstep is not None:
                bad["port/firmware mismatches"] = st.lockstep.mismatches
            found += [f"R1 {side} {name}: {v} {k}" for k, v in bad.items() if v]
            found += [f"  {e}" for e in st.examples] if any(bad.values()) else []
    for side, r in (("port", res.r2_port), ("firmware", res.r2_firmware)):
        if r is None:
            continue
        bad = {"executed": sum(r.executed.values()), "ACKed": sum(r.acked.values()),
               "crashes": r.crashes, "hangs": r.hangs,
               "commands not refused": r.commands - r.refused}
        if r.lockstep is not None:
            bad["port/firmware mismatches"] = r.lockstep.mismatches
        found += [f"R2 {side}: {v} {k}" for k, v in bad.items() if v]
        found += [f"  {e}" for e in r.examples] if any(bad.values()) else []
    for slices in (res.r1_firmware,):
        for st in slices.values():
            if st.lockstep and st.lockstep.examples:
                found += [f"  {e}" for e in st.lockstep.examples]
    if res.r2_firmware and res.r2_firmware.lockstep and res.r2_firmware.lockstep.examples:
        found += [f"  {e}" for e in res.r2_firmware.lockstep.examples]
    if res.r3 is not None:
        found += r3_problems(res.r3)
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small counts (seconds)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-simavr", action="store_true", help="the port only")
    for key in FULL:
        parser.add_argument("--" + key.replace("_", "-"), type=int, default=None)
    parser.add_argument("--r3-pace", type=float, default=1.0,
                        help="R3's board (and host clock) at this times real time (a loaded machine: 0.5)")
    args = parser.parse_args(argv)
    counts = dict(QUICK if args.quick else FULL)
    for key in FULL:
        value = getattr(args, key)
        if value is not None:
            counts[key] = value
    t0 = time.perf_counter()
    res = run(counts, args.seed, simavr=not args.no_simavr, log=True, r3_pace=args.r3_pace)
    print(markdown(res))
    found = problems(res)
    print()
    print("Problems:\n" + "\n".join(found) if found else "No problem found.")
    print(f"Wall time {time.perf_counter() - t0:.1f} s.")
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
