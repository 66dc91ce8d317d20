"""``feedback_form`` on the port: with 1, an unframed feedback line ends in the wheels'
speeds as a ros2_control hardware interface for the seed-era board reads them
(``r([pn])-?(\\d*\\.?\\d+)``, ``l([pn])-?(\\d*\\.?\\d+)``), the same numbers as its
``VEL`` fields; with 0 (the default), or on a framed line, the line is byte for byte
the seed's; the form is set with ``set:``, kept by ``save`` and loaded at boot.

The compiled firmware is held to these lines by the differential proof (the traces
set ``feedback_form``) and, on its pins and behind a pty, by
tests/tools/test_ros2_control_dropin.py."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.avr.arduino_print import print_float, print_long
from wcdrive.avr.f32 import f32
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware, setup
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
from wcdrive.firmware.state import FirmwareState
from wcdrive.hil.lockstep import compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import edges_from_trajectory
from wcdrive.protocol.codec import Feedback, frame, parse_line

#: The hardware interface's expressions, as it writes them.
PLUGIN_R = re.compile(r"r([pn])-?(\d*\.?\d+)")
PLUGIN_L = re.compile(r"l([pn])-?(\d*\.?\d+)")


def plugin_reads(line: bytes) -> tuple[float, float] | None:
    """(right, left) rad/s as the plugin takes them from one line, or None."""
    text = line.decode("ascii")
    r, l_ = PLUGIN_R.search(text), PLUGIN_L.search(text)
    if r is None or l_ is None:
        return None
    return ((-1.0 if r[1] == "n" else 1.0) * float(r[2]),
            (-1.0 if l_[1] == "n" else 1.0) * float(l_[2]))


def seed_line(s: FirmwareState) -> bytes:
    """The feedback line as the firmware printed it before ``feedback_form``."""
    return (b"ENC:" + print_long(s.encTickL) + b"," + print_long(s.encTickR) + b",VEL:"
            + print_float(s.rawVelL, 2) + b"," + print_float(s.rawVelR, 2) + b",MODE:"
            + C.MODE_NAMES[s.mode].encode() + b"\r\n")


counts = st.integers(-2**31, 2**31 - 1)
#: Wheel speeds as binary32, any the tick can measure and beyond (the tail's width).
speeds = st.floats(-1e4, 1e4, width=32).map(f32) | st.sampled_from([0.0, -0.0, -0.004, 0.005, -0.005])
modes = st.sampled_from(sorted(C.MODE_NAMES))


def state(count_l: int, count_r: int, vel_l: float, vel_r: float, mode: int, **kw: int) -> FirmwareState:
    s = FirmwareState(encTickL=count_l, encTickR=count_r, rawVelL=vel_l, rawVelR=vel_r, mode=mode)
    for name, value in kw.items():
        setattr(s, name, value)
    return s


@given(counts, counts, speeds, speeds, modes)
def test_form_1_appends_the_velocities_the_plugin_reads(count_l: int, count_r: int, vel_l: float,
                                                        vel_r: float, mode: int) -> None:
    s = state(count_l, count_r, vel_l, vel_r, mode, feedbackForm=1)
    line = feedback_line(s)
    seed = seed_line(s)
    assert line.startswith(seed[:-2]) and line.endswith(b"\r\n")
    tail = line[len(seed) - 2:-2]
    assert re.fullmatch(rb",r[pn]\d+\.\d\d,l[pn]\d+\.\d\d", tail), tail
    # what the plugin reads is what VEL says, to its 2 decimals, right first
    vel = parse_line(seed[:-2])
    assert isinstance(vel, Feedback)
    assert plugin_reads(line) == (vel.vel_right, vel.vel_left)
    # and the letter is the sign of the speed the board measured
    assert (tail[2:3] == b"n") == (vel_r < 0) and (tail.split(b",l")[1][:1] == b"n") == (vel_l < 0)
    # wcdrive's host parses the line as the seed's
    assert parse_line(line[:-2]) == vel


@given(counts, counts, speeds, speeds, modes, st.integers(0, C.FEEDBACK_FORM_MAX))
def test_form_0_and_framed_lines_are_the_seeds(count_l: int, count_r: int, vel_l: float,
                                               vel_r: float, mode: int, form: int) -> None:
    default = state(count_l, count_r, vel_l, vel_r, mode)
    assert default.feedbackForm == 0
    assert feedback_line(default) == seed_line(default)
    framed = state(count_l, count_r, vel_l, vel_r, mode, feedbackForm=form, linesFramed=1)
    assert feedback_line(framed) == seed_line(framed)


def test_the_default_line_is_byte_for_byte_the_seeds() -> None:
    s = state(-5170, 10335, f32(1.0), f32(2.004), C.MODE_WHEEL)
    assert feedback_line(s) == b"ENC:-5170,10335,VEL:1.00,2.00,MODE:WHEEL\r\n"
    s.feedbackForm = 1
    assert feedback_line(s) == b"ENC:-5170,10335,VEL:1.00,2.00,MODE:WHEEL,rp2.00,lp1.00\r\n"
    s.rawVelL, s.rawVelR = f32(-1.0), f32(-0.001)
    assert feedback_line(s) == b"ENC:-5170,10335,VEL:-1.00,-0.00,MODE:WHEEL,rn0.00,ln1.00\r\n"
    assert plugin_reads(feedback_line(s)) == (-0.0, -1.0)


def _ask(fw: Firmware, command: bytes) -> bytes:
    """``command``'s answer, then a tick (at most 3 commands are answered a tick)."""
    out = fw.feed(command)
    fw.tick(fw.state.lastControlTime + C.CONTROL_PERIOD_MS, 0, 0)
    return out


def test_set_get_and_its_range() -> None:
    fw = setup()
    assert _ask(fw, b"get:feedback_form\n") == b"PAR:feedback_form,0\r\n"
    assert _ask(fw, b"set:feedback_form=2\n") == b"ERR:range\r\n"
    assert _ask(fw, b"set:feedback_form=-1\n") == b"ERR:number\r\n"
    assert _ask(fw, b"set:feedback_form=1.0\n") == b"ERR:number\r\n"
    assert fw.state.feedbackForm == 0
    assert _ask(fw, b"set:feedback_form=0001\n") == b"PAR:feedback_form,1\r\n"
    assert fw.state.feedbackForm == 1
    assert _ask(fw, b"defaults\n") == b"" and fw.state.feedbackForm == 0


def test_save_keeps_it_across_a_reset() -> None:
    fw = setup()
    fw.feed(b"set:feedback_form=1\nsave\n")
    while fw.state.eeBusy:
        fw.eeprom_ready()
    again = Firmware(eeprom=fw.state.eeprom)
    assert again.boot_output().endswith(b"EVT:PARAMS_LOADED\r\n")
    assert again.state.feedbackForm == 1
    line = again.tick(again.due_after(0), 0, 0)
    assert line.startswith(b"ENC:0,0,VEL:0.00,0.00,MODE:CMDVEL,rp0.00,lp0.00\r\n")
    # a block of the layout before feedback_form (version 1) boots the defaults
    old = bytearray(again.state.eeprom)
    old[C.EEPROM_PARAMS_ADDR] = 1
    assert Firmware(eeprom=old).boot_output().endswith(b"EVT:PARAMS_DEFAULT,version\r\n")


def test_the_worst_unframed_tick_with_the_tail_fits_the_refill() -> None:
    """As tests/boards/test_serial_rings.py's worst tick, for a host that reads unframed
    lines (before hello, or after a plain hello, with ``TLM:``) and ``feedback_form`` 1:
    every field at its widest, the tail included."""
    s = FirmwareState(encTickL=-2**31, encTickR=-2**31, rawVelL=-1e30, rawVelR=-1e30,
                      tlmEnabled=1, feedbackForm=1, rxCount=2**32 - 1, lastSeq=65535, pwmL=255,
                      pwmR=255, illTickL=2**32 - 1, illTickR=2**32 - 1, rejectedCount=2**32 - 1,
                      crcRejected=2**32 - 1, freeRam=65535, faultFlags=511, rxLostTick=2**32 - 1,
                      lateTicks=2**32 - 1, pivotPhase=2)
    widest = feedback_line(s)
    assert widest.endswith(b",rn4294967040.00,ln4294967040.00\r\n") or b"ovf" in widest

    def sent(line: bytes) -> int:
        out = bytearray()
        send(FirmwareState(), line, out)
        return len(out)

    lines = [widest, send_telemetry(s, 2**32 - 1), send_event("WATCHDOG")]
    answered = []
    for i, p in enumerate(PARAMS):
        big = FirmwareState(tlmEnabled=1)
        setattr(big, p.field, p.high)
        out = bytearray()
        answer(big, None, 65535, DATA_PARAM, i, out)
        answered.append(len(out))
    out = bytearray()
    answer(FirmwareState(buildId="ffffffff"), None, 65535, DATA_HELLO, 0, out)
    answered.append(len(out))
    tick = sum(map(sent, lines)) + C.ERR_LINES_PER_TICK * max(answered)
    tick += sum(sent(send_event(e)) for e in ("PPM_LOST", "ESTOP", "ROLLAWAY"))
    assert tick <= min(C.CONTROL_PERIOD_MS * C.TX_CREDIT_PER_MS, C.TX_CREDIT_MAX)
    assert max(map(sent, lines)) <= C.TX_LINE_MAX


@pytest.mark.simavr
def test_the_firmware_prints_the_ports_tail() -> None:
    """The compiled firmware in simavr against the port, event by event (the lock-step
    differential): ``feedback_form`` 1 and ``save`` before hello, a wheel forward and one
    back, then a plain ``hello`` (unframed, with ``TLM:``: the tail stays) and
    ``hello:4`` (framed: it goes). Not one line nor global differs."""
    serial = [(0.02, b"set:feedback_form=1\n"), (0.05, b"save\n")]
    serial += [(0.1 + 0.1 * k, b"rp02.00,ln01.50,") for k in range(7)]
    serial += [(0.75, b"hello\n"), (1.05, frame(b"hello:4", 7)), (1.1, frame(b"rp2.0,ln1.5", 8))]
    # both counts rise: the right wheel forward, the mirrored left backward
    encoders = {side: edges_from_trajectory(np.array([0.0, 0.1, 1.4]), np.array([0.5, 0.5, 0.5 + rate]))
                for side, rate in (("left", 1500.0), ("right", 2000.0))}
    rec = record(Trace(duration=1.4, serial=serial, encoders=encoders))
    assert [str(m) for m in compare(rec).mismatches] == []
    lines = rec.tx.split(b"\r\n")
    hello = lines.index(next(line for line in lines if line.startswith(b"HELLO:3")))
    framed = lines.index(next(line for line in lines if line.startswith(b"HELLO:4")))
    before = [line for line in lines[:hello] if line.startswith(b"ENC:")]
    plain = [line for line in lines[hello:framed] if line.startswith(b"ENC:")]
    after = [line for line in lines[framed:] if line.startswith(b"ENC:")]
    assert before and plain and after
    assert all(re.search(rb",r[pn][\d.]+,l[pn][\d.]+$", line) for line in before + plain)
    assert any(b",rp" in line and b",ln" in line and plugin_reads(line) != (0.0, 0.0) for line in before)
    assert not any(b",r" in line.split(b"#")[0].split(b"MODE:")[1] for line in after)
    assert rec.events[-1].after["feedbackForm"] == 1
