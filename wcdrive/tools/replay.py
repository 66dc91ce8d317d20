"""Replay a recorded session through the Python port: proof that a board (a real Mega
on USB, or the firmware in simavr) and the port agree, byte for byte.

    wcdrive bench replay run.wcrec.json

The board's ``TLM:`` lines (protocol v2) carry every input of a tick that the host
cannot see: ``millis()``, how many received bytes the board had processed (``rx``),
the illegal-transition counts and the free RAM; the ``ENC:`` line carries the latched
encoder counts. So the port, started in its boot state, is fed the host's bytes up to
``rx`` and ticked with those inputs, and everything it sends (feedback, TLM with PWM
and DIR, replies, events) must equal what the board sent. Ticks before the hello
handshake have no TLM: their ``millis()`` follows from the Timer0 model from boot,
checked against the first TLM, and only the hello itself may be sent before it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

from wcdrive.avr.timer0 import millis_after
from wcdrive.errors import WcdriveFileError
from wcdrive.firmware.constants import CONTROL_PERIOD_MS
from wcdrive.firmware.eeprom import image_for
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import ExtendedTelemetry, Feedback, parse_line
from wcdrive.transports.recording import Recording


class ReplayError(WcdriveFileError):
    """The recording cannot be replayed (no boot line, commands before hello, ...)."""


@dataclass
class ReplayReport:
    """What ``replay`` found: ticks replayed, bytes compared and fed, the first mismatch
    (None when the board and the port agree) and notes."""

    ticks: int = 0
    bytes_compared: int = 0
    bytes_fed: int = 0
    mismatch: str | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def agrees(self) -> bool:
        """True when no byte differed."""
        return self.mismatch is None

    def __str__(self) -> str:
        verdict = "board and port agree" if self.agrees else f"MISMATCH: {self.mismatch}"
        return (f"ticks={self.ticks} bytes_compared={self.bytes_compared} "
                f"host_bytes_fed={self.bytes_fed}: {verdict}")


def _boot_tick_millis(start: int, count: int) -> list[int]:
    """``millis()`` of the first ``count`` ticks of a board whose setup() ended at
    ``millis() == start``: each tick at the first value >= the last + 50."""
    out: list[int] = []
    last, n = start, 0
    while len(out) < count:
        n += 1
        m = millis_after(n)
        if m - last >= CONTROL_PERIOD_MS:
            out.append(m)
            last = m
    return out


def _lines(data: bytes) -> list[bytes]:
    """Complete lines, each with its ``\\r\\n``."""
    parts = data.split(b"\r\n")
    return [p + b"\r\n" for p in parts[:-1]]


_BOOT = b"BOOT:final_control"


def replay(recording: Recording) -> ReplayReport:
    """Feeds ``recording`` to the port from its boot state, tick by tick (the module
    docstring says how), and compares what it sends with what the board sent. Raises
    ReplayError when the recording cannot be replayed.

    A board that reset during the recording (a ``BOOT:`` line after the first) is
    replayed boot by boot, each from a fresh port: the host's bytes that the board got
    after a reset start at a byte the host wrote within a second before that ``BOOT:``
    line arrived (or half a second after it), often in the middle of a line the reset
    cut; the first such byte (line starts first) with which the port agrees is taken
    (``notes`` says which)."""
    received = recording.received_bytes
    boots = []
    at = received.find(_BOOT)
    while at >= 0:
        boots.append(at)
        at = received.find(_BOOT, at + 1)
    if not boots:
        raise ReplayError("no BOOT line: the recording must start at the board's reset "
                          "(open the port so that the Mega resets, as connect() does)")
    sent = recording.sent_bytes
    if len(boots) == 1:
        return _replay_boot(received[boots[0]:], sent)
    report = ReplayReport()
    report.notes.append(f"the board reset {len(boots) - 1} time(s) during the recording")
    for j, start in enumerate(boots):
        segment = received[start:boots[j + 1] if j + 1 < len(boots) else len(received)]
        candidates = [0] if j == 0 else _offsets_near(recording, _time_at(recording.received, start))
        tried: list[tuple[int, ReplayReport]] = []
        for offset in candidates:
            try:
                attempt = _replay_boot(segment, sent[offset:])
            except ReplayError as exc:
                attempt = ReplayReport(mismatch=str(exc))
            tried.append((offset, attempt))
            if attempt.agrees:
                break
        if not tried:
            report.mismatch = f"boot {j}: no line the host wrote near that reset"
            break
        offset, best = next(((o, r) for o, r in tried if r.agrees),
                            max(tried, key=lambda item: item[1].ticks))
        report.ticks += best.ticks
        report.bytes_compared += best.bytes_compared
        report.bytes_fed = offset + best.bytes_fed
        if j:
            report.notes.append(f"boot {j}: the host's bytes from {offset} on")
        report.notes.extend(f"boot {j}: {note}" for note in best.notes)
        if not best.agrees:
            report.mismatch = f"boot {j}: {best.mismatch}"
            break
    return report


def _time_at(chunks: list[tuple[float, bytes]], index: int) -> float:
    """The host time of the chunk that holds byte ``index`` of the stream."""
    pos = 0
    for t, data in chunks:
        pos += len(data)
        if index < pos:
            return t
    return chunks[-1][0] if chunks else 0.0


def _offsets_near(recording: Recording, t: float) -> list[int]:
    """Offsets in the host's bytes written from 1 s before ``t`` to 0.5 s after it:
    where a line starts first, then the others (a reset may cut a line, and the new
    board gets its tail)."""
    starts: list[int] = []
    others: list[int] = []
    pos, previous = 0, ord("\n")
    for when, data in recording.sent:
        for k, byte in enumerate(data):
            if t - 1.0 <= when <= t + 0.5:
                (starts if previous == ord("\n") else others).append(pos + k)
            previous = byte
        pos += len(data)
    return starts + others


def _replay_boot(segment: bytes, sent: bytes) -> ReplayReport:
    """One boot: ``segment`` starts at its BOOT line; ``sent`` at the first byte the
    board may have received after that reset."""
    report = ReplayReport()
    lines = _lines(segment)[1:]
    # Ticks: each ENC line, its TLM (if any) and the lines between it and the next.
    tick_starts = [i for i, line in enumerate(lines) if line.startswith(b"ENC:")]
    while tick_starts and tick_starts[-1] + 1 >= len(lines):
        tick_starts.pop()                      # the last tick may be cut off
    if not tick_starts:
        raise ReplayError("no complete tick in the recording")
    tlm_of = {}
    for i in tick_starts:
        msg = parse_line(lines[i + 1].rstrip(b"\r\n")) if i + 1 < len(lines) else None
        if isinstance(msg, ExtendedTelemetry):
            tlm_of[i] = msg
    first_tlm = next((i for i in tick_starts if i in tlm_of), None)
    pre = tick_starts.index(first_tlm) if first_tlm is not None else len(tick_starts)
    # setup() ends within the first few ms: which millis() it saw decides the ticks.
    candidates = [s for s in range(0, 4)
                  if first_tlm is None
                  or _boot_tick_millis(s, pre + 1)[-1] == tlm_of[first_tlm].millis]
    if not candidates:
        raise ReplayError("the ticks before hello do not fit the Timer0 model")
    millis_pre = _boot_tick_millis(candidates[0], pre) if pre else []
    if pre:
        report.notes.append(f"{pre} ticks before hello, millis() from the Timer0 model")

    # setup()'s line about the parameters in EEPROM: the port boots from an EEPROM that
    # gives the same (a board that loaded saved values: the recording does not hold them,
    # so the port runs the defaults). A board without the line: the port skips it.
    event = lines[0].rstrip(b"\r\n")[4:].decode() if lines and lines[0].startswith(b"EVT:PARAMS_") else ""
    if event:
        fw = Firmware(eeprom=image_for(event))
        produced = bytearray(fw.boot_output().partition(b"\r\n")[2])
        if event == "PARAMS_LOADED":
            report.notes.append("the board loaded parameters saved in its EEPROM, which the "
                                "recording does not show: the port runs the defaults")
    else:
        fw = Firmware(FirmwareState())
        produced = bytearray()
    # setup() ends with lastControlTime = lastTickTime = millis(): both, or the first
    # tick's speeds are over a period 1 ms off once setup() runs past millis() 0
    fw.state.lastControlTime = fw.state.lastTickTime = candidates[0]
    recorded = b"".join(lines[:tick_starts[-1] + (2 if tick_starts[-1] in tlm_of else 1)])
    pos = 0
    for k, i in enumerate(tick_starts):
        # Replies recorded before this tick's lines (the watchdog event belongs to the tick).
        start = tick_starts[k - 1] + (2 if tick_starts[k - 1] in tlm_of else 1) if k else int(bool(event))
        end = i - 1 if i > 0 and lines[i - 1][:13] in (b"EVT:WATCHDOG\r", b"EVT:WATCHDOG#") else i
        between = b"".join(lines[start:end])
        if i in tlm_of:
            if tlm_of[i].rx_lost:
                report.mismatch = (f"tick {k}: the board lost {tlm_of[i].rx_lost} received bytes "
                                   "(TLM rx_lost): where they fell in the stream is not recorded, "
                                   "so the replay stops here")
                break
            rx = tlm_of[i].rx
            if rx < pos or rx > len(sent):
                report.mismatch = f"tick {k}: the board had received {rx} bytes, the host sent {len(sent)}"
                break
            produced += fw.feed(sent[pos:rx])
            pos = rx
        else:
            # Before hello: whole lines, only as many as the replies in this interval need.
            target = len(produced) + len(between)
            while len(produced) < target and pos < len(sent):
                nl = sent.find(b"\n", pos)
                nxt = len(sent) if nl < 0 else nl + 1
                produced += fw.feed(sent[pos:nxt])
                pos = nxt
        enc = parse_line(lines[i].rstrip(b"\r\n"))
        if not isinstance(enc, Feedback):
            report.mismatch = f"tick {k}: unreadable feedback line {lines[i]!r}"
            break
        tlm = tlm_of.get(i)
        if tlm is None and k >= len(millis_pre):
            following = lines[i + 1] if i + 1 < len(lines) else b""
            report.mismatch = f"tick {k}: no readable TLM line after hello: {following!r}"
            break
        now = tlm.millis if tlm else millis_pre[k]
        produced += fw.tick(now, enc.count_left, enc.count_right,
                            tlm.illegal_left if tlm else 0, tlm.illegal_right if tlm else 0,
                            free_ram=tlm.free_ram if tlm else None)
        report.ticks += 1
        upto = len(produced)
        if bytes(produced) != recorded[:upto]:
            where = next(j for j in range(upto) if j >= len(recorded) or produced[j] != recorded[j])
            report.mismatch = (f"tick {k} (millis {now}): byte {where}: port "
                               f"{bytes(produced[max(0, where - 40):where + 40])!r} board "
                               f"{recorded[max(0, where - 40):where + 40]!r}")
            break
    if report.agrees and pre and pos and first_tlm is None:
        report.notes.append("no TLM lines: bytes placed by their replies only")
    report.bytes_compared = len(produced)
    report.bytes_fed = pos
    return report


def main(path: Path) -> int:
    """``wcdrive bench replay PATH``: prints the report; 0 agree, 1 mismatch, 2 error."""
    try:
        report = replay(Recording.load(path))
    except ReplayError as exc:
        print(f"cannot replay {path}: {exc}", file=sys.stderr)
        return 2
    for note in report.notes:
        print(f"note: {note}")
    print(report)
    return 0 if report.agrees else 1
