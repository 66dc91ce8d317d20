"""R2, corrupted frames (``port_r2``, ``firmware_r2``), and the comparison with v1
lines before hello and a model of v2 (``legacy_rates``)."""

from __future__ import annotations

import copy
import random
import time
from dataclasses import fields

from wcdrive.firmware import commands
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import frame

from .common import (
    HANG_S,
    HELLO_FRAME,
    NEUTRAL_FRAME,
    NEUTRAL_LEGACY,
    NEUTRAL_TICKS,
    NEUTRAL_WAIT_S,
    PARAM_FIELDS,
    SEQ_MAX,
    TICK_MS,
    ElfPath,
    Legacy,
    Lockstep,
    Motion,
    R2Result,
    answer_kinds,
    is_stop,
    motion_in,
    motion_of,
    params_of,
)
from .inputs import cmdvel_command, corrupt
from .oracle import split_commands
from .r1 import PortBoard, byte_effects, lockstep_run


# ---- R2 ----------------------------------------------------------------------------
def _executed(fw: Firmware, rest: Motion, params: tuple[float | int, ...]) -> bool:
    s = fw.state
    return (bool(s.cmdSinceTick) or motion_of(s) != rest or params_of(s) != params
            or bool(s.estopLatched))


def port_r2(n: int, rng: random.Random) -> R2Result:
    """R2 on the port: ``n`` corrupted motion frames after hello and the neutral prelude,
    a tick after each."""
    res = R2Result()
    board = PortBoard(strict=True)
    res.preludes_failed += not board.neutral
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
            board = PortBoard(strict=True)
            res.preludes_failed += not board.neutral
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
            board = PortBoard(strict=True)
            res.preludes_failed += not board.neutral
        else:
            board.tick()
    return res


def firmware_r2(n: int, rng: random.Random, elf: ElfPath, chunk: int = 500) -> R2Result:
    """R2 on the firmware: chunks of ``chunk`` corrupted frames after hello and the
    neutral prelude (a stop, ``NEUTRAL_WAIT_S``), at wire speed. Nothing may change the
    motion, the parameters or the e-stop, arm the watchdog or be ACKed (the hello's and
    the stop's ACK aside), and every command must be refused."""
    totals = Lockstep()
    res = R2Result(lockstep=totals)
    while n > 0:
        count = min(chunk, n)
        n -= count
        lines = [corrupt(rng, frame(cmdvel_command(rng), rng.randint(0, SEQ_MAX)))
                 for _ in range(count)]
        data = b"".join(line for _, line in lines)
        prefix = HELLO_FRAME + NEUTRAL_FRAME
        rec, cycles = lockstep_run([(0.0, prefix), (NEUTRAL_WAIT_S, data)], elf, totals)
        if rec is None:
            res.crashes += 1
            continue
        line_of = [-1] * len(prefix)
        for i, (_, line) in enumerate(lines):
            line_of.extend([i] * len(line))
        executed = [False] * count
        rejected0 = None
        fw_rest = params0 = None
        for k, before, after in byte_effects(rec, cycles, totals):
            i = line_of[k]
            if i < 0:
                continue
            if rejected0 is None:
                res.preludes_failed += bool(before["needNeutral"])
                rejected0 = int(before["rejectedCount"])
                fw_rest = motion_in(before)
                params0 = tuple(before[f] for f in PARAM_FIELDS)
            if (after["cmdSinceTick"] or motion_in(after) != fw_rest or after["estopLatched"]
                    or tuple(after[f] for f in PARAM_FIELDS) != params0):
                executed[i] = True
        end = rec.events[-1].after
        res.refused += int(end["rejectedCount"]) - (rejected0 or 0)
        kinds = answer_kinds(rec.tx)
        acks = kinds.count("ACK") - 2                        # the hello's and the stop's
        res.answers.update(kinds)
        res.answers["ACK"] -= 2
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


def neutral_board() -> FirmwareState:
    """The state of a board at rest that never said hello, after the neutral prelude a
    host of the seed's era sends (``NEUTRAL_LEGACY``, then NEUTRAL_TICKS ticks)."""
    fw = Firmware()
    fw.feed(NEUTRAL_LEGACY)
    for k in range(1, NEUTRAL_TICKS + 3):
        fw.tick(k * TICK_MS, 0, 0)
        if not fw.state.needNeutral:
            return fw.state
    raise RuntimeError("the neutral prelude did not bring the board to neutral")


_MUTABLE = ("eeprom", "eeBlock", "cmdBuf", "profileTable")


def _clone(state: FirmwareState) -> Firmware:
    """A board in a copy of ``state`` (a shallow copy with its buffers and the drive
    profiles' table copied: a deep copy takes five times as long)."""
    s = copy.copy(state)
    for name in _MUTABLE:
        value = getattr(state, name)
        setattr(s, name, list(value) if isinstance(value, list) else bytearray(value))
    return Firmware(s)


def _outcome(fw: Firmware, intended: Motion, rest: Motion) -> str:
    s = fw.state
    m = motion_of(s)
    if not s.cmdSinceTick and m == rest:
        return "refused"
    if m == intended:
        return "same"
    return "stop" if is_stop(m) else "different"


def legacy_rates(n: int, rng: random.Random) -> Legacy:
    """``n`` corrupted v1 lines and ``n`` corrupted v2 frames (model), each on a fresh
    board at rest that never said hello, after its neutral prelude (``neutral_board``)."""
    res = Legacy()
    start = neutral_board()
    assert {f.name for f in fields(start)
            if isinstance(getattr(start, f.name), (bytearray, list, dict, set))} == set(_MUTABLE)
    rest = motion_of(start)
    for _ in range(n):
        cmd = cmdvel_command(rng)
        clean = _clone(start)
        clean.feed(cmd + b"\n")
        intended = motion_of(clean.state)
        kind, line = corrupt(rng, cmd + b"\n")
        fw = _clone(start)
        fw.feed(line)
        res.v1[kind, _outcome(fw, intended, rest)] += 1
        res.frames[kind] += 1
    saved = commands.unframe
    commands.unframe = v2_unframe  # type: ignore[assignment]   # the model: v3's port, v2's frame check
    try:
        for _ in range(n):
            cmd = cmdvel_command(rng)
            clean = _clone(start)
            clean.feed(cmd + b"\n")
            intended = motion_of(clean.state)
            kind, line = corrupt(rng, v2_frame(cmd, rng.randint(0, SEQ_MAX)))
            fw = _clone(start)
            out = fw.feed(line)
            outcome = _outcome(fw, intended, rest)
            res.v2[kind, outcome] += 1
            res.frames_v2[kind] += 1
            if outcome == "different" and b"ACK:" in out:
                res.v2_acked_different[kind] += 1
    finally:
        commands.unframe = saved
    return res


