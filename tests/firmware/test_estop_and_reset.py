"""Protocol v2 on the firmware in simavr: the e-stop in motion, reset after parking,
parameters that change the loop, TLM lines, the free-RAM figure and a reply flood
that must not drop a line. The same behaviour on the port is proven by the golden
vectors and the differential traces (which include every v2 command)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tests.support.boards import ChairOnPins, boot, neutral, send_and_run
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import FREE_RAM, Firmware
from wcdrive.plant.encoders import edges_from_trajectory
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line

pytestmark = pytest.mark.simavr


def _drive(mega: VirtualMega, command: bytes, seconds: float) -> bytes:
    out = b""
    for _ in range(round(seconds / 0.1)):
        out += send_and_run(mega, command, 0.1)
    return out


def test_estop_in_motion_ramps_down_refuses_motion_and_resets_once_parked(mega) -> None:
    rig = ChairOnPins(mega)
    rig.run_for(0.1)
    rig.neutral()
    for _ in range(15):
        rig.send_and_run(b"rp6.0,lp6.0,\n", 0.1)
    assert mega.read("setpointR") == pytest.approx(6.0)
    out = rig.send_and_run(b"estop\n", 0.06)
    assert b"EVT:ESTOP\r\n" in out and mega.read("estopLatched") == 1
    # Setpoints fall at estop_decel (15 rad/s^2): 6 rad/s -> 0 in 0.4 s, 0.75 per tick.
    before = mega.read("setpointR")
    rig.run_for(0.05)
    assert before - mega.read("setpointR") == pytest.approx(0.75, abs=0.06)
    assert b"ERR:estop" in rig.send_and_run(b"rp6.0,lp6.0,\n", 0.01)
    assert b"NAK:3,estop" in rig.send_and_run(frame(b"x:0.5,t:0.0,", 3), 0.01)
    assert b"ERR:busy" in rig.send_and_run(b"reset\n", 0.01)     # still braking
    rig.run_for(1.2)                              # the chair brakes to rest, then parks
    assert mega.read("parked") == 1 and mega.pwm("left") == 0 and mega.pwm("right") == 0
    assert max(abs(v) for v in rig.speeds()) < 0.3
    assert b"ERR:" not in rig.send_and_run(b"reset\n", 0.06)
    assert mega.read("estopLatched") == 0
    assert mega.read("setpointR") == 0.0          # a reset alone does not move the chair
    # Neutral before motion: the released e-stop takes a neutral command before motion.
    assert b"ERR:neutral" in rig.send_and_run(b"rp2.0,lp2.0,\n", 0.2)
    assert mega.read("targetR") == 0.0 and mega.read("setpointR") == 0.0
    rig.neutral()
    rig.send_and_run(b"rp2.0,lp2.0,\n", 0.2)
    assert mega.read("targetR") == 2.0 and mega.read("setpointR") > 0.0


def test_watchdog_timeout_parameter(mega) -> None:
    boot(mega, 0.1)
    assert b"PAR:watchdog_ms,200\r\n" in send_and_run(mega, b"set:watchdog_ms=200\n", 0.01)
    neutral(mega)
    send_and_run(mega, b"rp3.0,lp3.0,\n", 0.0)
    sent_at = mega.cycle
    out = b""
    while b"EVT:WATCHDOG" not in out:
        mega.run_for(0.01)
        out += bytes(b for _, b in mega.take_tx())
    waited = (mega.cycle - sent_at) / 16e6
    assert 0.2 <= waited <= 0.2 + 0.05 + 0.012


def test_gains_and_ramp_parameters_change_the_loop(mega) -> None:
    boot(mega, 0.1)
    send_and_run(mega, b"set:max_accel=2.0\n", 0.01)
    neutral(mega)
    send_and_run(mega, b"rp5.0,lp5.0,\n", 0.0)
    start = mega.read("setpointR")
    mega.run_for(0.05)
    assert mega.read("setpointR") - start == pytest.approx(0.1, abs=1e-6)   # 2 rad/s^2 * 50 ms
    send_and_run(mega, b"set:kp_r=1\nset:ki_r=0.01\nset:kd_r=0\n", 0.06)
    error = mega.read("setpointR") - mega.read("filtVelR")
    assert abs(mega.read("outputR")) <= abs(error) * 1.0 + 0.05      # the gains at their floor


def test_tlm_lines_follow_feedback_after_hello_and_carry_the_tick_inputs(mega) -> None:
    boot(mega, 0.1)
    neutral(mega)
    out = send_and_run(mega, b"hello\n" + frame(b"rp1.0,lp1.0,", 41), 0.3)
    assert b"HELLO:3,final_control,%s,%s,0\r\n" % (C.FIRMWARE_VERSION.encode(), C.BUILD_ID.encode()) in out
    assert b"ACK:41\r\n" in out
    lines = out.split(b"\r\n")
    tlm = [parse_line(line) for line in lines if line.startswith(b"TLM:")]
    assert len(tlm) >= 5 and all(isinstance(t, ExtendedTelemetry) for t in tlm)
    for i, line in enumerate(lines):
        if line.startswith(b"TLM:"):
            assert lines[i - 1].startswith(b"ENC:")
    last = tlm[-1]
    assert last.seq == 41 and last.free_ram == FREE_RAM
    assert last.pwm_right == mega.pwm("right") and last.dir_right == mega.direction("right")
    assert last.millis == mega.read("lastControlTime")
    assert last.rx == mega.read("rxCount")
    assert [b - a for a, b in zip([t.millis for t in tlm], [t.millis for t in tlm[1:]],
                                  strict=False)] == [50] * (len(tlm) - 1)


def test_free_ram_figure_of_the_port_is_the_builds(mega) -> None:
    """The simulated board reports FREE_RAM; it must be what this ELF measures."""
    boot(mega, 0.06)
    assert mega.read("freeRam") == FREE_RAM == Firmware().free_ram


def test_a_flood_of_answers_never_drops_a_line(mega) -> None:
    """The worst burst: every window full of the longest answers, events and TLM."""
    boot(mega, 0.06)
    send_and_run(mega, b"hello\n", 0.06)
    flood = b"".join(frame(b"set:estop_decel=50", 60000 + i) for i in range(40))
    flood += b"estop\n" + b"".join(frame(b"rp99,lp1,", 65000 + i) for i in range(40))
    out = send_and_run(mega, flood, 1.0)
    assert mega.read("txDropped") == 0
    assert mega.read("errSuppressed") > 0
    assert re.search(rb"PAR:estop_decel,50.0000\r\nACK:600\d\d\r\n", out)
    assert re.search(rb"NAK:650\d\d,range\r\n", out)


def test_emergency_stops_end_with_the_motors_unpowered(mega) -> None:
    """After the e-stop's ramp the PID no longer drives the motors on its integrators:
    PWM 0 as soon as the setpoints reach zero, even while the wheels still turn."""
    boot(mega, 0.1)
    neutral(mega)
    _drive(mega, b"rp3.0,lp3.0,\n", 1.0)
    # The wheels keep turning at 1 rad/s (a chair rolling on), whatever the motors do.
    t0 = mega.time
    counts_per_rad = 10000 / (2 * math.pi)
    for side, sign in (("left", -1), ("right", 1)):
        travel = np.array([0.5, 0.5 + sign * 2.0 * counts_per_rad])
        mega.encoder_edges(side, edges_from_trajectory(np.array([0.0, 2.0]), travel), t0)
    send_and_run(mega, b"estop\n", 0.0)
    ramp = mega.read("setpointR") / 15.0
    mega.run_for(ramp + 0.1)
    assert mega.read("setpointR") == 0.0 and mega.read("parked") == 1
    assert mega.pwm("left") == 0 and mega.pwm("right") == 0
    assert abs(mega.read("filtVelR")) > 0.5                 # still rolling: parked anyway
