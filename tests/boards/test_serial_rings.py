"""The serial rings, honest on both sides.

RX: the harness models the USART's two-frame FIFO and its data overrun; the sketch's
own RX interrupt counts every loss (a full ring, an overrun) and marks where it
happened; ``loop()`` hands the mark to ``rxGap``, which throws the damaged command away
(``ERR:overrun``). The port takes the mark as an input and must answer the same.
``hil.lockstep.compare`` checks every byte the host sent against what the firmware
received, and that the control tick keeps running.

TX: an output budget (``txCredit``) decides which lines go, on the firmware and the port
alike; it stays below what the UART drains, so the TX ring never fills.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from tests.support.recordings import chatter
from wcdrive._util.resources import firmware_dir
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware, boot_line
from wcdrive.firmware.state import FirmwareState
from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import edges_from_trajectory
from wcdrive.protocol.can_frames import BOOT_CAUSES, REASONS
from wcdrive.protocol.codec import frame

pytestmark = pytest.mark.simavr

ACK = re.compile(rb"ACK:(\d+)\r\n")


def storm_during_a_stream() -> Trace:
    """hello, then 40 zero-speed frames back to back on the wire, and a 500k edges/s
    storm on both encoders in the middle of the stream: the encoder interrupts (higher
    priority than USART0_RX) hold the RX interrupt off until the storm guard masks them,
    about 17,000 cycles, more than the USART's three frames last."""
    serial = [(0.02, frame(b"hello", 1)),
              (0.06, b"".join(frame(b"x:0.0,t:0.0", 2 + k) for k in range(40)))]
    # At 0.105 s the gap's ERR:overrun is within its tick's three answers (at 0.1 s, with
    # the drive profiles' Timer0 phase, it was the fourth: suppressed, and counted).
    encoders = {side: chatter(0.105, 0.01, 500_000) for side in ("left", "right")}
    return Trace(duration=0.6, serial=serial, encoders=encoders)


@pytest.fixture(scope="module")
def storm() -> Recording:
    return record(storm_during_a_stream())


def test_an_overrun_is_counted_marked_and_answered_alike(storm: Recording) -> None:
    overruns = [loss for loss in storm.rx_lost if loss.cause == "overrun"]
    assert len(overruns) >= 3                              # the harness's USART overran
    report = compare(storm)
    assert report.mismatches == []                         # the port answered the same
    assert report.lost_bytes == 0 and report.stalls == 0
    assert report.rx_lost == 1                             # one overrun, counted once
    assert [e.kind for e in storm.events].count("gap") == 1
    assert b"ERR:overrun\r\n" in storm.tx
    # The frame that lost bytes was not executed: no ACK for it.
    hit = overruns[0].index
    wire = bytes(b for _, b in storm.rx_wire)
    start = wire.rindex(b"$", 0, hit)
    seq = int(wire[start + 1:wire.index(b":", start)])
    assert seq not in {int(s) for s in ACK.findall(storm.tx)}


def test_the_port_never_runs_a_line_that_lost_a_byte() -> None:
    """The port, given the same mark: the command before the gap and the piece after it
    up to the next ',' or line end are thrown away, with one ERR:overrun; the next line
    runs."""
    fw = Firmware()
    fw.feed(frame(b"hello", 1))
    fw.tick(50, 0, 0)
    fw.tick(100, 0, 0)
    moving = frame(b"x:0.5,t:0.0", 2)
    out = fw.feed(moving[:6])
    fw.rx_gap()
    out += fw.feed(moving[9:])
    assert out == b"ERR:overrun\r\n"          # up to the line end: no comma after the gap
    assert fw.state.targetL == 0.0 and fw.state.targetR == 0.0
    assert fw.state.rxGaps == 1
    fw.tick(150, 0, 0)
    assert fw.feed(frame(b"x:0.0,t:0.0", 3)) == b"ACK:3\r\n"
    # Seed-form commands end at their last comma: a gap inside one drops it and the
    # rest up to the next comma; nothing else.
    seed = Firmware()
    out = seed.feed(b"x:0.")
    seed.rx_gap()
    out += seed.feed(b"3,t:0.0,x:0.2,t:0.0,")
    assert out.count(b"ERR:overrun") == 1 and seed.state.cmdLen == 0


def test_compare_sees_a_byte_lost_unseen(storm: Recording) -> None:
    """Drop one byte the firmware received from the recording (as a firmware whose RX
    ring loses bytes silently would): compare reports it."""
    events = list(storm.events)
    k = next(i for i, e in enumerate(events) if e.kind == "byte" and i > 40)
    events[k - 1] = dataclasses.replace(events[k - 1], after=events[k].after)
    del events[k]
    report = compare(dataclasses.replace(storm, events=events))
    assert report.lost_bytes >= 1
    assert any(m.field == "RX" for m in report.mismatches)


def test_compare_sees_a_gap_mark_that_went_missing(storm: Recording) -> None:
    events = [e for e in storm.events if e.kind != "gap"]
    report = compare(dataclasses.replace(storm, events=events))
    assert report.lost_bytes >= 1


def test_compare_sees_a_firmware_that_stops_ticking(storm: Recording) -> None:
    """No tick for 200 ms (a loop() starved by an encoder storm, a frozen millis()):
    the ticks there removed from the recording; and a millis() that stands still."""
    t0, t1 = round(0.2 * F_CPU), round(0.4 * F_CPU)
    ticks = [i for i, e in enumerate(storm.events) if e.kind == "tick" and t0 <= e.cycle < t1]
    assert len(ticks) >= 3
    events = [e for i, e in enumerate(storm.events) if i not in ticks[1:]]
    report = compare(dataclasses.replace(storm, events=events))
    assert report.stalls >= 1
    assert any(m.field == "stall" and "none for" in m.firmware for m in report.mismatches)
    frozen = list(storm.events)
    for i in ticks[1:]:
        frozen[i] = dataclasses.replace(frozen[i], arg=frozen[ticks[0]].arg)
    assert compare(dataclasses.replace(storm, events=frozen)).stalls >= 1


def test_a_trace_that_ends_early_is_a_stall(storm: Recording) -> None:
    """The last stretch counts too: a firmware that stops ticking before the end."""
    last = max(i for i, e in enumerate(storm.events) if e.kind == "tick")
    cut = dataclasses.replace(storm, end_cycle=storm.events[last].cycle + round(0.2 * F_CPU))
    assert compare(cut).stalls == 1


# ---- TX: the output budget -------------------------------------------------------------
def test_the_budget_refills_per_millisecond_and_caps() -> None:
    fw = Firmware()
    # setup()'s parameters line (EVT:PARAMS_...) is the budget's first: the BOOT line is not.
    assert fw.state.txCredit == C.TX_CREDIT_BOOT - len(fw.boot_output().partition(b"\r\n")[2])
    fw.state.txCredit = 10
    assert fw.feed(frame(b"hello", 1)) == b"ACK:1\r\n"       # HELLO (38 bytes) does not fit
    assert fw.state.txCredit == 3 and fw.state.txDropped == 1
    fw.state.lastTickTime = 40
    out = fw.tick(50, 0, 0)                                 # + 10 ms x 10 bytes
    assert out.startswith(b"ENC:") and b"TLM:" in out
    assert fw.state.txCredit == 3 + 10 * C.TX_CREDIT_PER_MS - len(out)
    out = fw.tick(10_000, 0, 0)                             # a long pause: full, not more
    assert fw.state.txCredit == C.TX_CREDIT_MAX - len(out)


#: The widest fault field: the faults that can latch together are one group's (the
#: wheels' and the driver's, else the brake's, else the windings', else the supply's,
#: else the current senses'), at most 5 digits: the current sense's bit alone, 16384.
WIDEST_FAULTS = 0x4000


def test_the_worst_tick_fits_the_refill() -> None:
    """The published budget (protocol/PROTOCOL.md, "Output budget"): the longest tick a
    host can cause, every field at its widest and every line framed (v4), is no more
    than what one period restores, so the board drops no line however it is flooded;
    only a fault burst on top can. And the longest line fits ``LineBuffer``'s buffer."""
    s = FirmwareState(encTickL=-2**31, encTickR=-2**31, rawVelL=-1e30, rawVelR=-1e30,
                      tlmEnabled=1, linesFramed=1, rxCount=2**32 - 1, lastSeq=65535, pwmL=255,
                      pwmR=255, illTickL=2**32 - 1, illTickR=2**32 - 1, rejectedCount=2**32 - 1,
                      crcRejected=2**32 - 1, freeRam=65535, faultFlags=WIDEST_FAULTS, rxLostTick=2**32 - 1,
                      lateTicks=2**32 - 1, pivotPhase=2, estopLatched=1, emergencyStop=1, parked=1,
                      watchdogArmed=1)
    from wcdrive.firmware.output import (
        DATA_HELLO,
        DATA_PARAM,
        answer,
        feedback_line,
        send,
        send_event,
        send_telemetry,
    )
    from wcdrive.firmware.params import PARAMS

    def sent(line: bytes) -> int:
        out = bytearray()
        send(FirmwareState(linesFramed=1, lineCounter=255), line, out)
        return len(out)

    # the state at its widest: every bit (both inhibit inputs, push mode, a brake, hot, a
    # low battery, the last drive profile), and the supply at the ADC's full scale
    # (29.97 V: 300 tenths)
    s.neutralFault, s.inhibitStable, s.brakeFitted, s.thermalRollback, s.batteryLow = 1, 7, 1, 1, 1
    s.profile = C.PROFILE_MAX
    s.supplyVolts = 1023 * C.SUPPLY_VOLTS_PER_COUNT
    assert send_telemetry(s, 0).endswith(b",1023,300\r\n")
    # the tick's own event: WATCHDOG, or (never beside it) one of the wait for neutral's
    tick_event = max((send_event(e) for e in ("WATCHDOG", "NOT_NEUTRAL", "NEUTRAL", "DEFLECTED")),
                     key=sent)
    lines = [feedback_line(s), send_telemetry(s, 2**32 - 1), tick_event]
    tick = sum(map(sent, lines))
    answered = []                      # a data line comes only with an ACK
    for i, p in enumerate(PARAMS):     # every parameter at its largest
        big = FirmwareState(tlmEnabled=1, linesFramed=1)
        setattr(big, p.field, p.high)
        out = bytearray()
        answer(big, None, 65535, DATA_PARAM, i, out)
        answered.append(len(out))
    out = bytearray()
    widest = FirmwareState(buildId="ffffffff", linesFramed=1, profile=C.PROFILE_MAX)
    answer(widest, None, 65535, DATA_HELLO, 0, out)
    answered.append(len(out))
    longest_nak = max(sent(b"NAK:65535,%s\r\n" % reason.encode()) for reason in REASONS)
    answers = C.ERR_LINES_PER_TICK * max(*answered, longest_nak)
    events = sum(sent(send_event(e)) for e in ("PPM_LOST", "ESTOP", "ROLLAWAY"))
    worst = tick + answers + events
    assert worst == WORST_TICK_BYTES      # the figure PROTOCOL.md gives
    assert worst <= min(C.CONTROL_PERIOD_MS * C.TX_CREDIT_PER_MS, C.TX_CREDIT_MAX)
    assert max(map(sent, lines)) <= C.TX_LINE_MAX


#: The widest tick a host can cause (protocol/PROTOCOL.md, "Output budget").
WORST_TICK_BYTES = 494


def test_the_tx_ring_holds_the_budget_and_the_2_ms() -> None:
    """The firmware's TX ring (the Makefile's ``SERIAL_TX_BUFFER_SIZE``, one slot kept
    empty) holds the most the budget lets the board queue: the credit at its largest, or
    the boot credit behind the longest ``BOOT:`` line, and the 2 ms of refill by which
    ``millis()`` may run ahead of the UART between two ticks. So a line the budget lets
    through never waits on the UART."""
    makefile = (firmware_dir() / "Makefile").read_text()
    size = int(re.search(r"-DSERIAL_TX_BUFFER_SIZE=(\d+)", makefile)[1])   # type: ignore[index]
    ahead = 2 * C.TX_CREDIT_PER_MS
    boot = max(len(boot_line(cause)) for cause in BOOT_CAUSES)
    assert C.TX_CREDIT_MAX + ahead <= size - 1
    assert boot + C.TX_CREDIT_BOOT + ahead <= size - 1


def test_a_flood_at_top_speed_is_accounted_for_byte_by_byte() -> None:
    """hello:4, then set: and get: frames back to back on the wire for 2 s with both
    wheels at top speed (28,000 edges/s each): loop() falls behind now and then (the RX
    ring fills while a tick formats its lines and a set: is parsed and answered), so a
    few bytes are lost; every loss is marked, counted and answered as the port answers
    it, no TX line is dropped and the TX ring never fills."""
    bodies = [b"set:kp_l=1.2345678901234567890123", b"set:estop_decel=12.345678901234567890",
              b"get:kp_r"]
    # driven at top speed, so each tick runs the PID (a parked chair's hold is lighter)
    data = frame(b"hello:4", 0) + frame(b"rp17.5,lp17.5", 1) + b"".join(
        frame(bodies[k % 3], k) for k in range(2, 400))
    top = 28_000
    encoders = {side: edges_from_trajectory(np.array([0.0, 0.02, 2.2]),
                                            sign * np.array([0.5, 0.5, 0.5 + top * 2.18]))
                for side, sign in (("left", -1.0), ("right", 1.0))}   # the left is mirrored
    rec = record(Trace(duration=2.2, serial=[(0.02, data)], encoders=encoders))
    report = compare(rec)
    assert [str(m) for m in report.mismatches] == []
    assert report.lost_bytes == 0 and report.stalls == 0
    last = rec.events[-1].after
    assert last["txRingFull"] == 0 and last["txDropped"] == 0
    assert report.rx_lost == last["rxLost"] > 0                     # losses happened, all seen
    gaps = [e for e in rec.events if e.kind == "gap"]
    assert sum(e.arg for e in gaps) == last["rxGaps"] <= last["rxLost"]
    assert rec.tx.count(b"ERR:overrun") + last["errSuppressed"] >= 1
    framed = rec.tx[rec.tx.index(b"HELLO:4"):]
    assert last["linesFramed"] == 1 and framed.count(b"\n") == framed.count(b"#") > 100


def test_lines_over_the_budget_are_dropped_alike() -> None:
    """The drop path on the chip: the budget lowered in SRAM and in the port's state at
    the same point; the same lines go, the same are counted."""
    mega = VirtualMega()
    mega.run_for(0.03)
    mega.write("txCredit", 50, "H")
    port = Firmware(FirmwareState(lastControlTime=int(mega.read("lastControlTime")), txCredit=50))
    mega.take_tx()
    line = frame(b"hello", 7) + frame(b"get:kp_l", 8)
    mega.send(line)
    mega.run_for(len(line) * 1500 / F_CPU + 0.008)       # and the TX ring drained
    assert mega.read("lastControlTime") == port.state.lastControlTime      # no tick between
    sent = bytes(b for _, b in mega.take_tx())
    assert sent == port.feed(line)
    assert sent.startswith(b"HELLO:") and b"PAR:" not in sent      # 38 + 7 bytes fit, no more
    assert mega.read("txDropped") == port.state.txDropped == 2
    assert mega.read("txCredit") == port.state.txCredit
    mega.close()
