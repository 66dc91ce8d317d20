"""R1, random and mutated lines: on the port (``port_r1``) and on the firmware in
simavr through the lock-step harness (``firmware_r1``, whose helpers R2 uses too)."""

from __future__ import annotations

import math
import random
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING

from wcdrive.firmware.final_control import Firmware

if TYPE_CHECKING:
    from wcdrive.hil.lockstep import Recording

from .common import (
    HANG_S,
    HELLO_FRAME,
    NEUTRAL_TICKS,
    NEUTRAL_WAIT_S,
    PARAM_FIELDS,
    TICK_MS,
    ElfPath,
    Lockstep,
    R1Slice,
    Sram,
    answer_kinds,
    is_stop,
    motion_in,
    motion_of,
    neutral_prelude,
    params_of,
)
from .inputs import r1_lines
from .oracle import line_valid


# ---- R1 on the port ----------------------------------------------------------------
class PortBoard:
    """A port ``Firmware`` with its clock and the chair (``wcdrive.plant``) on its
    motors: at each tick the plant has run the 50 ms since the last under the duty that
    tick set, and the encoders count its wheels. R1 tests the parser: the random
    command stream whips the chair about (a new motion every 50 ms) until the encoder
    fault checks take a wheel for reversed or stalled, which latches a fault
    that refuses motion until a ``reset`` once parked; so a latched fault is cleared
    after its tick (``faults`` counts them). ``strict`` says hello first. Then the
    neutral prelude a host sends after boot (``neutral_prelude``), ticked until the board
    no longer waits for neutral (``neutral``: it does not, at most NEUTRAL_TICKS + 2
    ticks later)."""

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
        self.fw.feed(neutral_prelude(strict))
        for _ in range(NEUTRAL_TICKS + 2):
            self.tick()
            if not self.fw.state.needNeutral:
                break
        self.neutral = not self.fw.state.needNeutral

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
                stopped: bool, check: bool = True, neutral_motion: bool = False,
                refused_neutral: bool = False) -> None:
    """Books one line's outcome (``answers`` None: not attributed to the line; ``check``
    False: counted only; ``neutral_motion``: it drove while the board waited for
    neutral; ``refused_neutral``: a valid drive refused ``neutral`` while it waited)."""
    st.lines[source] += 1
    if neutral_motion:
        st.neutral_motions += 1
        if len(st.examples) < 10:
            st.examples.append(f"{'strict' if strict else 'legacy'} {source} {line!r}: "
                               "drove while the board waited for neutral")
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
    if source == "drive" and refused_neutral:
        st.refused_neutral += 1
        return
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
    """R1 on the port: ``n`` lines, a tick after each, on a board that had its neutral
    prelude. Whether the board waits for neutral is read from its state
    (``needNeutral``) before the line and after it."""
    st = R1Slice()
    board = PortBoard(strict)
    st.preludes_failed += not board.neutral
    clock = time.perf_counter
    for source, line in r1_lines(rng, n, strict):
        s = board.fw.state
        m0, p0, sup0 = motion_of(s), params_of(s), s.errSuppressed
        waiting = bool(s.needNeutral)
        t0 = clock()
        try:
            out = board.fw.feed(line)
        except Exception as error:                      # a crash: book it, boot again
            st.crashes += 1
            st.lines[source] += 1
            if len(st.examples) < 10:
                st.examples.append(f"crash on {line!r}: {error!r}")
            board = PortBoard(strict)
            st.preludes_failed += not board.neutral
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
        st.neutral_waits += bool(s.needNeutral) and not waiting
        refused = (waiting and not drove
                   and any(kind in ("ERR:neutral", "NAK:neutral") for kind in kinds))
        _check_line(st, source, line, strict, drove, accepted, params_of(s) != p0, kinds,
                    is_stop(m1), neutral_motion=drove and (waiting or bool(s.needNeutral)),
                    refused_neutral=refused)
        waiting = bool(s.needNeutral)
        board.tick()
        st.neutral_waits += bool(s.needNeutral) and not waiting
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


def lockstep_run(chunks: list[tuple[float, bytes]], elf: ElfPath,
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


def byte_effects(rec: Recording, cycles: list[int], totals: Lockstep) -> Iterator[tuple[int, Sram, Sram]]:
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


def neutral_waits(rec: Recording) -> int:
    """The waits for neutral the firmware began in this run after its first (the boot's,
    which the prelude ends): ``needNeutral`` going from 0 to 1."""
    previous = int(rec.initial["needNeutral"])
    waits = 0
    for ev in rec.events:
        flag = int(ev.after["needNeutral"])
        waits += flag and not previous
        previous = flag
    return waits


def _exec_offset(line: bytes, strict: bool) -> int:
    """Where in a valid command's line the board acts on it: at the line end for a frame,
    at the comma of its last field for a bare command."""
    return len(line) - 1 if strict else len(line.rstrip(b"\r\n")) - 1


def _book_latches(st: R1Slice, rec: Recording) -> None:
    """Counts the faults the firmware latched in this run, by flags."""
    previous = int(rec.initial["faultFlags"])
    for ev in rec.events:
        flags = int(ev.after["faultFlags"])
        if flags and not previous:
            st.latched[flags] += 1
        previous = flags


def firmware_r1(n: int, rng: random.Random, elf: ElfPath, chunk: int | None = None
                ) -> dict[str, R1Slice]:
    """R1 on the firmware: chunks of ``chunk`` lines (default: 300, or a tenth of ``n``
    for small runs), four strict ones to a legacy one, each after the neutral prelude
    (the hello, a stop, ``NEUTRAL_WAIT_S``). Whether the board waits for neutral is read
    from its SRAM (``needNeutral``) at each byte."""
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
        prefix = (HELLO_FRAME if strict else b"") + neutral_prelude(strict)
        line_of = [-1] * len(prefix)
        exec_at = [-1] * count
        chunks = [(0.0, prefix)]
        for i, (source, line) in enumerate(lines):
            pause = rng.uniform(0.0, 0.060) if rng.random() < 0.05 else 0.0
            chunks.append(((NEUTRAL_WAIT_S if i == 0 else 0.0) + pause, line))
            if source == "drive":
                exec_at[i] = len(line_of) + _exec_offset(line, strict)
            line_of.extend([i] * len(line))
        rec, cycles = lockstep_run(chunks, elf, st.lockstep)
        if rec is None:
            st.crashes += 1
            st.lines.update(source for source, _ in lines)
            continue
        drove = [False] * count
        params = [False] * count
        latched = [False] * count
        in_wait = [False] * count           # drove while the board waited for neutral
        refused = [False] * count           # a valid drive refused: waiting for neutral
        sup0 = None
        _book_latches(st, rec)
        st.neutral_waits += neutral_waits(rec)
        for k, before, after in byte_effects(rec, cycles, st.lockstep):
            i = line_of[k]
            if i < 0:
                continue
            if sup0 is None:
                sup0 = int(before["errSuppressed"])
                st.preludes_failed += bool(before["needNeutral"])
            if before["faultFlags"]:
                latched[i] = True
            m1 = motion_in(after)
            arm = bool(after["cmdSinceTick"]) and not before["cmdSinceTick"]
            if not is_stop(m1) and (arm or m1 != motion_in(before)):
                drove[i] = True
                if before["needNeutral"] or after["needNeutral"]:
                    in_wait[i] = True
            if (k == exec_at[i] and before["needNeutral"] and after["notNeutralSent"]
                    and not after["neutralSeen"] and after["rejectedCount"] != before["rejectedCount"]):
                refused[i] = True
            if any(before[f] != after[f] for f in PARAM_FIELDS):
                params[i] = True
        end = rec.events[-1].after if rec.events else rec.initial
        st.suppressed += int(end["errSuppressed"]) - (sup0 or 0)
        kinds = answer_kinds(rec.tx)
        if strict:                                  # the hello's answers and the stop's aside
            for kind in ("HELLO", "ACK", "ACK"):
                if kind in kinds:
                    kinds.remove(kind)
        for kind in kinds:
            st.answers["all", kind] += 1
        for i, (source, line) in enumerate(lines):
            # Only driving controls are checked here: a stop or a get/set may leave no
            # trace in SRAM when the state already matches; the port checks those. A
            # valid drive that came while a fault was latched is refused, as it must be;
            # so is one that came while the board waited for neutral (``refused``).
            if source == "drive" and not drove[i] and latched[i]:
                st.lines[source] += 1
                st.controls[source] += 1
                st.refused_latched += 1
                continue
            _check_line(st, source, line, strict, drove[i], False, params[i], None, False,
                        check=source in ("random", "mutated", "drive"), neutral_motion=in_wait[i],
                        refused_neutral=refused[i])
    for st in slices.values():
        assert st.lockstep is not None
        st.worst_s = st.lockstep.max_latency_s
        st.hangs = (int(st.lockstep.max_latency_s > HANG_S) + int(st.lockstep.max_tick_gap_ms >= 2 * TICK_MS)
                    + st.lockstep.lost_bytes)
        st.crashes += st.lockstep.extra_boots
    return slices


