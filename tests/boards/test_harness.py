"""The lock-step simavr harness: encoder stimulus, PWM/DIR, SRAM by
symbol, determinism, the pty and VCD output."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest
import serial

from tests.support.boards import FEEDBACK, NEUTRAL, ChairOnPins, boot, neutral, send_and_run
from wcdrive.boards.simavr.mega_board import MegaBoard
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory, state_for_count
from wcdrive.transports.pty_bridge import PtyBridge

pytestmark = pytest.mark.simavr


def ramp_counts(counts: float, start: float = 0.02, duration: float = 0.5) -> EdgeTrain:
    return edges_from_trajectory(np.array([0.0, start, start + duration]),
                                 np.array([0.5, 0.5, 0.5 + counts]))


@pytest.mark.parametrize(("left", "right"), [(1000, -2500), (-3000, 777), (12345, 12345)])
def test_encoder_edges_give_the_expected_counts(mega: VirtualMega, left: int, right: int) -> None:
    mega.encoder_edges("left", ramp_counts(left))
    mega.encoder_edges("right", ramp_counts(right))
    mega.run_for(0.65)
    lines = FEEDBACK.findall(bytes(b for _, b in mega.take_tx()))
    assert (int(lines[-1][0]), int(lines[-1][1])) == (left, right)
    assert mega.read("illegalL") == 0 and mega.read("illegalR") == 0


def test_both_directions_and_reversal(mega: VirtualMega) -> None:
    train = edges_from_trajectory(np.array([0.0, 0.02, 0.2, 0.4]), np.array([0.5, 0.5, 800.5, -300.5]))
    mega.encoder_edges("right", train)
    mega.run_for(0.5)
    assert mega.read("encoderValueR") == train.end_count == -301


def test_illegal_transitions_are_counted_not_stepped(mega: VirtualMega) -> None:
    boot(mega, 0.02)
    base = mega.cycle + 1000
    # 11 -> 00 (both pins at once) -> 11: two illegal transitions, no count.
    for k, state in enumerate([0b00, 0b11, 0b00, 0b11]):
        train = EdgeTrain(np.array([k * 1e-4]), np.array([state]), 0, 0)
        mega.encoder_edges("left", train, t0=base / F_CPU)
    mega.run_for(0.01)
    assert mega.read("illegalL") == 4
    assert mega.read("encoderValueL") == 0


def test_fifty_thousand_edges_per_second_are_all_counted(mega: VirtualMega) -> None:
    """Below the storm guard's threshold (STORM_EDGES per 1.024 ms, twice the top
    speed) every edge counts: 50,000 edges/s for half a second."""
    train = edges_from_trajectory(np.array([0.0, 0.01, 0.51]), np.array([0.5, 0.5, 25000.5]))
    assert np.min(np.diff(train.times)) == pytest.approx(1 / 50000, rel=1e-6)
    mega.encoder_edges("left", train)
    mega.run_for(0.6)
    assert mega.read("encoderValueL") == 25000 and mega.read("illegalL") == 0
    assert mega.read("stormL") == 0


@pytest.mark.parametrize("phase", [0.0, 0.25, 0.5, 0.9])
def test_seventy_thousand_edges_per_second_on_both_wheels_are_all_counted(mega: VirtualMega,
                                                                        phase: float) -> None:
    """The timing budget's goal: 70,000 edges/s on both wheels at once (2.5 times top speed), the
    right wheel's edges ``phase`` of an edge interval after the left's (0: coincident),
    for 0.3 s: every edge counted, none illegal, no storm."""
    rate, seconds = 70_000.0, 0.3
    left = edges_from_trajectory(np.array([0.0, 0.01, 0.01 + seconds]),
                                 np.array([0.5, 0.5, 0.5 + rate * seconds]))
    shift = phase / rate
    right = edges_from_trajectory(np.array([0.0, 0.01 + shift, 0.01 + shift + seconds]),
                                  np.array([0.5, 0.5, 0.5 - rate * seconds]))
    mega.encoder_edges("left", left)
    mega.encoder_edges("right", right)
    mega.run_for(0.4)
    assert mega.read("encoderValueL") == left.end_count and mega.read("encoderValueR") == right.end_count
    assert mega.read("illegalL") == 0 and mega.read("illegalR") == 0
    assert mega.read("stormL") == 0 and mega.read("stormR") == 0


def test_ninety_thousand_edges_per_second_trip_the_storm_guard(mega: VirtualMega) -> None:
    """90,000 edges/s is more than three times the wheel's top speed (28,000 edges/s):
    the ISR masks the encoder within one 1.024 ms window, after STORM_EDGES edges at
    most, and the tick latches an implausible-encoder fault."""
    train = edges_from_trajectory(np.array([0.0, 0.1, 0.6]), np.array([0.5, 0.5, 45000.5]))
    mega.encoder_edges("left", train)
    mega.run_for(0.7)
    assert mega.read("stormL") != 0 and mega.read("stormR") == 0
    counted = mega.read("encoderValueL")
    assert 0 < counted <= 2 * C.STORM_EDGES
    assert mega.read("faultFlags") == 0x10               # ENC_IMPLAUSIBLE_L
    assert b"EVT:FAULT,ENC_IMPLAUSIBLE_L\r\n" in bytes(b for _, b in mega.take_tx())


def test_quadrature_states_follow_the_seed_table() -> None:
    assert [state_for_count(c) for c in range(5)] == [0b11, 0b01, 0b00, 0b10, 0b11]


def test_commands_give_expected_pwm_and_dir(mega: VirtualMega) -> None:
    boot(mega)
    neutral(mega)
    send_and_run(mega, b"rp4.0,ln4.0,", 0.101)    # two ticks: setpoints 0.25 and 0.5
    # With still wheels the PID output is Kp*e + Ki*integral; the port says exactly
    # (its own neutral command first, two ticks).
    from wcdrive.firmware.final_control import Firmware

    port = Firmware(boot_millis=int(mega.read("lastControlTime")) - 200)
    now = port.state.lastControlTime
    for command in (NEUTRAL, b"rp4.0,ln4.0,"):
        port.feed(command)
        for _ in range(2):
            now += 50
            port.tick(now, 0, 0)
    assert (mega.pwm("left"), mega.pwm("right")) == (port.state.pwmL, port.state.pwmR)
    assert mega.direction("right") == 1 and mega.direction("left") == 0
    assert 0 < mega.pwm("right") < 255


def test_full_duty_reads_255(mega: VirtualMega) -> None:
    # Windings of 1 ohm: the motors droop and the PID saturates. (A weak battery no longer
    # does: the supply sense reads it, and below 21 V the board cuts off.)
    rig = ChairOnPins(mega, armature_resistance=1.0)
    # Booted, a neutral command, and the host's commands from 0.2 s: 3.9 s of them, as
    # from 0.1 s before neutral before motion (the one at 0 s, sent during setup(), was
    # garbled: ERR:syntax).
    rig.run_for(0.06)
    rig.neutral(seconds=0.14)
    for _ in range(39):
        rig.send_and_run(b"rp17.59,lp17.59,", 0.1)
    assert mega.pwm("left") == 255 and mega.pwm("right") == 255   # analogWrite(255) is digitalWrite


def test_read_named_float(mega: VirtualMega) -> None:
    boot(mega)
    neutral(mega)
    send_and_run(mega, b"rp5.0,lp3.0,", 0.11)
    assert mega.read("targetR") == 5.0
    assert mega.read("setpointR") in (0.25, 0.5, 0.75)
    assert mega.read_raw("targetL") == np.float32(3.0).tobytes()


def _run_trace(elf) -> tuple[list, list]:
    with VirtualMega(elf) as mega:
        mega.encoder_edges("left", ramp_counts(5000))
        mega.send(b"x:0,t:0,\n", at=int(0.02 * F_CPU))      # neutral first
        mega.send(b"x:0.5,t:0.3,\n", at=int(0.15 * F_CPU))
        mega.send(b"junk,rp1,lp2,", at=int(0.4 * F_CPU))
        mega.run_for(1.0)
        return mega.take_tx(), [(h.cycle, h.function, h.arg) for h in mega.take_hits()]


def test_two_runs_of_one_trace_are_identical(elf) -> None:
    first, second = _run_trace(elf), _run_trace(elf)
    assert first == second
    assert len(first[0]) > 500


def test_pyserial_talks_to_the_pty(elf) -> None:
    with PtyBridge(MegaBoard(elf).start()) as board:
        port = serial.Serial(board.path, 115200, timeout=2)
        try:
            got = b""
            deadline = time.monotonic() + 20
            while b"MODE:CMDVEL" not in got and time.monotonic() < deadline:
                got += port.read(port.in_waiting or 1)
            port.write(b"x:0,t:0,\n")               # neutral first; it stands 2 ticks
            got = b""
            while got.count(b"MODE:CMDVEL") < 4 and time.monotonic() < deadline:
                got += port.read(port.in_waiting or 1)
            port.write(b"rp1.5,lp1.5,\n")
            got = b""
            while b"MODE:WHEEL" not in got and time.monotonic() < deadline:
                got += port.read(port.in_waiting or 1)
            assert b"MODE:WHEEL" in got and b"ERR:" not in got
        finally:
            port.close()


def test_vcd_output(elf, tmp_path) -> None:
    path = tmp_path / "run.vcd"
    with VirtualMega(elf, vcd=path) as mega:
        mega.encoder_edges("left", ramp_counts(200, duration=0.05))
        boot(mega, 0.1)
        send_and_run(mega, b"rp2,lp2,", 0.2)
    text = path.read_text()
    for name in ("enc_l_a", "enc_l_b", "dir_l", "uart_tx", "uart_rx", "pwm_left"):
        assert re.search(rf"\$var wire \d+ \S+ {name} \$end", text), name
    assert "#" in text.split("$enddefinitions")[1]


def test_millis_model_matches_the_firmware(mega: VirtualMega) -> None:
    """timer0_millis is millis_after(overflows), and overflows come every 16,384 cycles."""
    from wcdrive.avr.timer0 import OVERFLOW_CYCLES, millis_after

    samples = []
    rng = np.random.default_rng(3)
    for step in rng.integers(1000, 400_000, size=300):
        mega.run_until(mega.cycle + int(step))
        samples.append((mega.cycle, mega.read("timer0_overflow_count"), mega.read("timer0_millis")))
    # A sample may land inside the overflow ISR, after it stored millis and before
    # it counted the overflow: then millis is one overflow ahead.
    exact = 0
    for _cycle, overflows, millis in samples:
        assert millis in (millis_after(overflows), millis_after(overflows + 1))
        exact += millis == millis_after(overflows)
    assert exact >= 0.95 * len(samples)
    # One phase c0 explains every sample: overflows == (cycle - c0) // 16384.
    lo = max(c - (n + 1) * OVERFLOW_CYCLES for c, n, _ in samples)
    hi = min(c - n * OVERFLOW_CYCLES for c, n, _ in samples)
    assert lo < hi + 8   # within an instruction's length
