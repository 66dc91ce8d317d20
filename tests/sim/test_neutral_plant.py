"""Neutral before motion, watched from the plant (docs/safety.md, "Neutral before
motion"): a command that was in force before a boot, a reset or a watchdog stop moves
nothing until a neutral command comes; the firmware's side of it is
tests/firmware/test_neutral.py.

- ``SteppedChair(neutral=False)``: the port and the plant, stepped;
- the bundled ``neutral_at_switch_on`` and ``fault_reset`` (a host streaming across a
  board reset) on both backends, held to their ``[expect]`` contracts;
- a pty whose reopening resets the board (DTR), on the in-process board and on the
  compiled firmware in simavr, while a host written as the seed's keeps streaming its
  last command across the reopen: the wheels stand until it sends a zero command.
"""

from __future__ import annotations

import itertools
import re
import time

import pytest
import serial

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.sim import contract, runner, scenario
from wcdrive.testing.stepped import NEUTRAL_CONFIRM_S, SteppedChair
from wcdrive.transports.pty_bridge import PtyBridge

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
_VEL = re.compile(rb"ENC:-?\d+,-?\d+,VEL:(-?\d+\.\d+),(-?\d+\.\d+),MODE:\w+\r\n")


def _moved(chair: SteppedChair, x0: float) -> float:
    return chair.pose[0] - x0


def test_a_stepped_chair_streamed_from_switch_on_stands_until_a_stop() -> None:
    chair = SteppedChair(neutral=False)
    for _ in range(20):                       # 2 s of 0.5 m/s, from the boot
        chair.set_velocity(0.5, 0.0)
        chair.run(0.1)
    assert abs(_moved(chair, 0.0)) < 0.002
    assert list(chair.events).count("NOT_NEUTRAL") == 1
    chair.stop()
    chair.run(NEUTRAL_CONFIRM_S)
    x0 = chair.pose[0]
    for _ in range(10):
        chair.set_velocity(0.5, 0.0)
        chair.run(0.1)
    assert _moved(chair, x0) > 0.1                  # 1 s from standing, up the ramp
    assert "NEUTRAL" in chair.events


def test_a_stepped_chair_drives_at_once_after_its_neutral() -> None:
    """The default: a neutral command first, as ``connect`` sends it."""
    chair = SteppedChair()
    for _ in range(10):
        chair.set_velocity(0.5, 0.0)
        chair.run(0.1)
    assert chair.pose[0] > 0.1 and "NOT_NEUTRAL" not in chair.events


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["neutral_at_switch_on", "fault_reset"])
def test_streamed_commands_across_a_boot_keep_the_contract(name: str, backend: str) -> None:
    sc = scenario.load(name)
    misses = contract.check(sc, runner.run(sc, backend=backend))
    assert not misses, "\n".join(map(str, misses))


def _stream(link: serial.Serial, command: bytes, ticks: int) -> bytes:
    """``command`` about every 50 ms, as the seed's CMDVEL host writes it, until the
    board has sent ``ticks`` feedback lines (its own time, however fast it runs); what
    it sent meanwhile."""
    out = b""
    deadline = time.monotonic() + 30.0
    while out.count(b"ENC:") < ticks:
        assert time.monotonic() < deadline, out[-300:]
        link.write(command)
        step = time.monotonic() + 0.05
        while time.monotonic() < step:
            out += link.read(512)
    return out


def _speeds(data: bytes) -> list[float]:
    """The wheels' measured speeds (rad/s, the faster of the two) of each feedback line."""
    return [max(abs(float(left)), abs(float(right))) for left, right in _VEL.findall(data)]


def _board(kind: str) -> tuple[object, PtyBridge]:
    if kind == "sim":
        board = SimulatedBoard()
        return board, PtyBridge(board.start(), on_open=board.dtr).start()
    from wcdrive.boards.simavr.build import firmware_elf
    from wcdrive.boards.simavr.mega_board import MegaBoard

    mega = MegaBoard(firmware_elf(), realtime=True)
    return mega, PtyBridge(mega.start(), on_open=mega.dtr).start()


@pytest.mark.parametrize("kind", ["sim", pytest.param("avr", marks=pytest.mark.simavr)])
def test_a_host_streaming_across_a_reopen_moves_nothing_until_its_zero(kind: str) -> None:
    """The seed's host: a zero command, then 0.5 m/s at 20 Hz; it closes and reopens the
    port (the board resets, as a Mega does on DTR) and streams the same command on:
    ``ERR:neutral``, and the wheels stand; a zero command, and the stream drives again."""
    board, bridge = _board(kind)
    forward, zero = b"x:0.500,t:0.000,\n", b"x:0.000,t:0.000,\n"
    try:
        with serial.Serial(bridge.device, 115200, timeout=0.01) as link:
            _stream(link, zero, 6)                            # the boot, and a neutral command
            first = _stream(link, forward, 30)
        assert max(_speeds(first)[-5:]) > 2.0, first[-300:]   # 0.5 m/s is 3.3 rad/s
        with serial.Serial(bridge.device, 115200, timeout=0.01) as link:   # a reset
            across = _stream(link, forward, 30)
            _stream(link, zero, 4)
            after = _stream(link, forward, 20)
        assert b"BOOT:final_control,EXTERNAL" in across
        booted = across[across.index(b"BOOT:final_control,EXTERNAL"):]
        assert b"ERR:neutral" in booted and b"EVT:NOT_NEUTRAL" in booted
        speeds = _speeds(booted)              # coasting from the reset, then standing
        assert len(speeds) >= 20 and max(speeds[-12:]) < 0.05, booted[-300:]
        assert all(b <= a + 0.05 for a, b in itertools.pairwise(speeds)), speeds
        assert max(_speeds(after)[-5:]) > 2.0, after[-300:]
    finally:
        bridge.close()
        board.close()  # type: ignore[attr-defined]
