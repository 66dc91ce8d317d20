"""final_control in simavr: boot, feedback timing, every command kind, every malformed
case, the watchdog, stops and PPM loss."""

from __future__ import annotations

import itertools
import math
import re

import pytest

from tests.conftest import thorough
from tests.support.boards import FEEDBACK, NEUTRAL, NEUTRAL_PPM, ChairOnPins, boot, ms, neutral, send_and_run
from wcdrive.avr.f32 import f32
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware.final_control import Firmware

pytestmark = pytest.mark.simavr

CONTROL = ("targetL", "targetR", "setpointL", "setpointR", "mode", "pivotPhase", "pivotTicksLeft",
           "integralL", "integralR", "pwmL", "pwmR", "dirL", "dirR", "emergencyStop")


def test_boots_and_sends_feedback_every_50ms(mega: VirtualMega) -> None:
    mega.run_for(2.0)
    tx = mega.take_tx()
    text = bytes(b for _, b in tx)
    assert text.startswith(b"BOOT:final_control,POWER_ON\r\n")
    starts = [cycle for k, (cycle, b) in enumerate(tx)
              if b == ord("E") and bytes(x for _, x in tx[k:k + 4]) == b"ENC:"]
    assert len(starts) >= 38
    periods = [ms(b - a) for a, b in itertools.pairwise(starts)]
    assert all(abs(p - 50.0) <= 1.5 for p in periods), periods
    assert len(FEEDBACK.findall(text)) == len(starts)
    assert mega.relay() == 1


VALID = [
    (b"rp5.0,lp3.0,", "WHEEL", f32(5.0), f32(3.0)),
    (b"rn2.5,ln2.5,\n", "WHEEL", f32(-2.5), f32(-2.5)),
    (b"x:0.500,t:0.100,", "CMDVEL", None, None),          # the seed host's form, no newline
    (b"x:0.5,t:0.2,\r\n", "CMDVEL", None, None),
    (b"ppm:1500,2000,1500,1500,1500,1500,1500,1500,", "PPM", f32(5.0), f32(5.0)),
    (b"ppm:1500,1500,1500,1750,1500,1500,1500,1500\n", "PPM", f32(-2.5), f32(2.5)),
]


@pytest.mark.parametrize(("command", "mode", "right", "left"), VALID)
def test_answers_each_command_kind(mega: VirtualMega, command: bytes, mode: str,
                                   right: float | None, left: float | None) -> None:
    zero = NEUTRAL_PPM if mode == "PPM" else NEUTRAL     # the host's neutral command first
    boot(mega)
    neutral(mega, zero)
    out = send_and_run(mega, command, 0.12)
    lines = FEEDBACK.findall(out)
    assert lines and lines[-1][4].decode() == mode
    port = Firmware()
    port.tick(50, 0, 0)
    port.feed(zero)
    port.tick(100, 0, 0)
    port.tick(150, 0, 0)
    port.feed(command)
    assert mega.read("targetR") == port.state.targetR
    assert mega.read("targetL") == port.state.targetL
    if right is not None:
        assert (port.state.targetR, port.state.targetL) == (right, left)
    # The wheels stay still, so the PID drives both motors in the commanded direction.
    expected_dir = (1 if port.state.targetL >= 0 else 0, 1 if port.state.targetR >= 0 else 0)
    assert (mega.direction("left"), mega.direction("right")) == expected_dir
    assert mega.pwm("left") > 0 and mega.pwm("right") > 0


def test_seed_kinematics_example(mega: VirtualMega) -> None:
    boot(mega)
    neutral(mega)
    send_and_run(mega, b"x:0.5,t:0.2,", 0.06)
    assert mega.read("targetR") == pytest.approx(3.65, abs=0.005)
    assert mega.read("targetL") == pytest.approx(2.91, abs=0.005)


def test_newline_less_command_takes_effect_at_the_next_tick(mega: VirtualMega) -> None:
    boot(mega, 0.075)
    neutral(mega, seconds=0.1)     # stood 2 ticks; still between ticks
    cycles = mega.send(b"x:0.500,t:0.100,")
    done = cycles[-1] + 1500
    mega.break_on("controlTick")
    assert mega.run_to_break(done + F_CPU)
    tick_cycle = mega.hit_log[-1].cycle
    assert ms(tick_cycle - done) <= 51.0
    mega.break_on()
    mega.run_for(0.005)
    assert mega.read("setpointR") > 0.0


MALFORMED = [
    (b"x:0.5\n", "fields"),
    (b"rp1.0\r", "fields"),
    (b"x:0.5,y:1.0,t:0.1,", "syntax"),
    (b"t:0.1,x:0.5,", "syntax"),
    (b"howdy\n", "syntax"),
    (b"X:0.5,T:0.1,", "syntax"),
    (b"rp 1.0,lp1.0,", "syntax"),
    (b"x:0.5\x00,t:0.1,", "syntax"),
    (b"rp1.0,lp1.0\xff,", "syntax"),
    (b",", "syntax"),
    (b"rp1.0x,lp1.0,", "number"),
    (b"x:,t:1,", "number"),
    (b"x:1.0.0,t:0,", "number"),
    (b"rp-1.0,lp1.0,", "number"),
    (b"x:nan,t:0.1,", "number"),
    (b"rpinf,lp1,", "number"),
    (b"x:-nan,t:0.1,", "range"),
    (b"x:-inf,t:0,", "range"),
    (b"rp18.0,lp1.0,", "range"),
    (b"x:2.69,t:0.0,", "range"),
    (b"x:0.0,t:9.5,", "range"),
    (b"x:1e39,t:0,", "range"),
    (b"x:0." + b"1" * 80 + b",t:0.1,", "overlong"),
    (b"ppm:1500,1500\n", "fields"),
    (b"ppm:1500,15a0,1500,1500,1500,1500,1500,1500,", "number"),
    (b"ppm:15000,1500,1500,1500,1500,1500,1500,1500,", "number"),
    (b"ppm:,1500,1500,1500,1500,1500,1500,1500,", "number"),
]


@pytest.mark.parametrize(("command", "reason"), MALFORMED)
def test_rejects_malformed_commands_at_rest(mega: VirtualMega, command: bytes, reason: str) -> None:
    boot(mega, 0.3)
    before = mega.snapshot(CONTROL)
    rejected = mega.read("rejectedCount")
    mega.send(command)
    pwm_seen = set()
    for _ in range(30):
        mega.run_for(0.005)
        pwm_seen.add((mega.pwm("left"), mega.pwm("right")))
    out = bytes(b for _, b in mega.take_tx())
    errors = re.findall(rb"ERR:(\w+)\r\n", out)
    assert errors and errors[0].decode() == reason, out
    assert mega.read("rejectedCount") > rejected
    assert mega.snapshot(CONTROL) == before
    assert pwm_seen == {(0, 0)}


@pytest.mark.parametrize(("command", "reason"), MALFORMED)
def test_malformed_commands_change_nothing_in_motion(elf, command: bytes, reason: str) -> None:
    """The same valid command stream with and without a malformed line in it: the
    controller ends in the same state."""
    results = []
    for extra in (b"", command):
        with VirtualMega(elf) as mega:
            boot(mega)
            neutral(mega)
            send_and_run(mega, b"x:0.400,t:0.100,", 0.22)
            send_and_run(mega, extra, 0.1)
            send_and_run(mega, b"x:0.400,t:0.100,", 0.1)
            results.append(mega.snapshot(CONTROL))
    assert results[0] == results[1]


def _pwm_zero_time(rig: ChairOnPins, until: float) -> tuple[float | None, float]:
    """Steps 1 ms at a time; the first time from which both PWM outputs stay 0, and the
    fastest true wheel speed (rad/s) at that moment."""
    mega = rig.mega
    zero_since = None
    fastest_at_zero = math.inf
    while mega.time < until:
        rig.run_for(0.001)
        if mega.pwm("left") == 0 and mega.pwm("right") == 0:
            if zero_since is None:
                zero_since = mega.time
                fastest_at_zero = max(abs(v) for v in rig.speeds())
        else:
            zero_since = None
    return zero_since, fastest_at_zero


#: rad/s: the slowest and the top speed at the fast depth, the two between as well at the
#: thorough one (the run grows with the speed: 0.6 to 2.9 s on simavr).
WATCHDOG_SPEEDS = [0.5, 3.0, 10.0, 17.59] if thorough() else [0.5, 17.59]


@pytest.mark.parametrize("speed", WATCHDOG_SPEEDS)
def test_watchdog_brakes_the_chair_then_unpowers_the_motors(mega: VirtualMega, speed: float) -> None:
    """After the last command the watchdog ramps the setpoints down and the PID keeps
    braking the wheels until they turn slower than BRAKE_DONE_SPEED; then the motors are
    unpowered (parked). The chair on the pins is the ground truth."""
    rig = ChairOnPins(mega)
    rig.run_for(0.06)
    rig.neutral()
    command = f"rp{speed},lp{speed},".encode()
    settle = speed / 5.0 + 0.5
    t = mega.time
    while mega.time - t < settle:        # a host repeating its command until the ramp is done
        rig.send_and_run(command, 0.1)
    last = mega.send(command)[-1] / F_CPU
    assert mega.read("setpointR") == pytest.approx(speed, abs=1e-4)
    # The plant brakes at most ~7.4 rad/s^2 (the driver's 13 A limit): budget 6 rad/s^2.
    deadline = last + 0.5 + speed / 6.0 + 0.3
    zero_at, speed_at_zero = _pwm_zero_time(rig, deadline + 0.5)
    assert zero_at is not None and zero_at <= deadline, (zero_at, deadline)
    assert speed_at_zero < 0.5, "unpowered while the wheels still turned fast"
    out = bytes(b for _, b in mega.take_tx())
    assert b"EVT:WATCHDOG\r\n" in out and b"EVT:FAULT" not in out
    assert mega.read("integralL") == 0.0 and mega.read("integralR") == 0.0
    assert mega.read("parked") == 1


def test_stop_command_leaves_the_motors_unpowered(mega: VirtualMega) -> None:
    rig = ChairOnPins(mega)
    rig.run_for(0.06)
    rig.neutral()
    for _ in range(10):
        rig.send_and_run(b"rp2.0,lp2.0,", 0.1)
    assert mega.pwm("left") > 0
    rig.send_and_run(b"rp0,lp0,", 0.0)
    zero_at, _ = _pwm_zero_time(rig, mega.time + 1.5)
    assert zero_at is not None
    assert mega.read("parked") == 1 and mega.read("integralR") == 0.0
    assert max(abs(v) for v in rig.speeds()) < 0.05


def test_ppm_loss_stops_and_is_reported(mega: VirtualMega) -> None:
    rig = ChairOnPins(mega)
    rig.run_for(0.06)
    rig.neutral(NEUTRAL_PPM)
    frame = b"ppm:1500,1800,1500,1500,1500,1500,1500,1500,"
    for _ in range(8):
        rig.send_and_run(frame, 0.05)
    assert mega.read("targetR") == f32(3.0)
    out = rig.send_and_run(b"ppm:1500,0,1500,1500,1500,1500,1500,1500,", 0.05)
    assert b"EVT:PPM_LOST\r\n" in out
    assert mega.read("targetR") == 0.0 and mega.read("emergencyStop") == 1
    assert _pwm_zero_time(rig, mega.time + 1.0)[0] is not None
    assert mega.read("mode") == 2


def test_reversal_stops_pivots_then_applies_the_command(mega: VirtualMega) -> None:
    rig = ChairOnPins(mega)
    rig.run_for(0.06)
    rig.neutral()
    for _ in range(5):
        rig.send_and_run(b"x:0.3,t:0,", 0.1)
    rig.send_and_run(b"x:-0.3,t:0,", 0.01)
    assert mega.read("pivotPhase") == 1                       # stopping first
    assert (mega.read("targetR"), mega.read("targetL")) == (0.0, 0.0)
    phases = []
    for k in range(60):
        if k % 2 == 0:                       # the host keeps sending at 10 Hz
            mega.send(b"x:-0.3,t:0,")
        rig.run_for(0.05)
        phases.append((mega.read("pivotPhase"), mega.read("targetR"), mega.read("targetL")))
        if phases[-1][0] == 0:
            break
    rotating = [p for p in phases if p[0] == 2]
    assert rotating and all(p[1:] == (2.0, -2.0) for p in rotating)
    assert 5 <= len(rotating) <= 6                            # 6 ticks, sampled every 50 ms
    assert phases[-1][0] == 0
    assert mega.read("targetR") < 0 and mega.read("targetL") < 0
    assert mega.read("faultFlags") == 0


def test_stop_command_cancels_a_pivot(mega: VirtualMega) -> None:
    rig = ChairOnPins(mega)
    rig.run_for(0.06)
    rig.neutral()
    for _ in range(5):
        rig.send_and_run(b"x:0.3,t:0,", 0.1)
    rig.send_and_run(b"x:-0.3,t:0,", 0.03)
    assert mega.read("pivotPhase") == 1
    rig.send_and_run(b"x:0,t:0,", 0.06)
    assert mega.read("pivotPhase") == 0
    assert (mega.read("targetR"), mega.read("targetL")) == (0.0, 0.0)
    assert mega.read("faultFlags") == 0


def test_no_heap_and_stack_headroom(mega: VirtualMega) -> None:
    boot(mega, 0.5)
    assert "__brkval" not in mega.variables or mega.read_bytes(mega.address_of("__brkval")[0], 2) == b"\0\0"
    assert mega.free_ram() > 5500      # 5,858 (6,000 was the bound before the TX ring's 512 B more)
