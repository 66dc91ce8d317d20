"""Hosts of the seed's era, against the firmware in simavr with the chair on its pins:
one that never says hello gets the seed's lines, unframed, and drives. Two such hosts
exist: the guide's CMDVEL host (``x:0.500,t:0.100,`` with no line end) and a
ros2_control hardware interface for this chair, which writes ``rp05.00,lp03.00,``
wheel commands with no line end at 100 Hz. Each opens with a neutral command, as the
board asks after a boot ("Neutral before motion"): the ros2_control interface writes
``rp0.0,lp0.0,`` and a line end and waits 2 s before streaming, and the guide's host
forwards ROS cmd_vel, zero (``x:0.000,t:0.000,``) until someone drives."""

from __future__ import annotations

import pytest

from tests.support.boards import FEEDBACK, ChairOnPins, boot
from wcdrive.boards.simavr.virtual_mega import VirtualMega

pytestmark = pytest.mark.simavr


def _drive(mega: VirtualMega, opening: list[tuple[bytes, float]], command: bytes, rate_hz: float,
           seconds: float) -> tuple[bytes, bytes]:
    """The host's ``opening`` (each write, then the time until the next), then
    ``command`` at ``rate_hz`` for ``seconds``: what the board sent during each."""
    chair = ChairOnPins(mega)
    boot(mega)
    first = bytearray()
    for data, wait in opening:
        first += chair.send_and_run(data, wait)
    out = bytearray()
    for _ in range(round(seconds * rate_hz)):
        out += chair.send_and_run(command, 1.0 / rate_hz)
    return bytes(first), bytes(out)


def _seed_lines(out: bytes) -> list[tuple[bytes, ...]]:
    """Every line is the seed's feedback line, whole and unframed."""
    lines = out.split(b"\r\n")
    assert lines[-1] == b""
    assert all(FEEDBACK.fullmatch(line + b"\r\n") for line in lines[:-1]), [
        line for line in lines[:-1] if not FEEDBACK.fullmatch(line + b"\r\n")][:3]
    return [m.groups() for m in FEEDBACK.finditer(out)]


def test_the_ros2_control_host_drives_at_100_hz_without_line_ends(elf) -> None:
    with VirtualMega(elf) as mega:
        opening, out = _drive(mega, [(b"rp0.0,lp0.0,\n", 2.0)], b"rp05.00,lp03.00,", 100.0, 3.0)
        # the 2 s wait outlasts the watchdog: it stops the zero command (nothing to stop)
        assert opening.count(b"EVT:WATCHDOG\r\n") == 1
        _seed_lines(opening.replace(b"EVT:WATCHDOG\r\n", b""))
        fields = _seed_lines(out)
        assert len(fields) >= 59                            # 20 Hz feedback, none lost
        assert {f[4] for f in fields[5:]} == {b"WHEEL"}
        assert (mega.read("targetR"), mega.read("targetL")) == (5.0, 3.0)
        vel_l, vel_r = float(fields[-1][2]), float(fields[-1][3])     # still closing in
        assert 0.85 * 5.0 < vel_r <= 5.2 and 0.85 * 3.0 < vel_l <= 3.2
        assert mega.read("rejectedCount") == 0 and mega.read("linesFramed") == 0
        assert mega.read("faultFlags") == 0


def test_the_guides_cmdvel_host_drives_without_line_ends(elf) -> None:
    with VirtualMega(elf) as mega:
        opening, out = _drive(mega, [(b"x:0.000,t:0.000,", 0.1)] * 3, b"x:0.500,t:0.100,", 10.0, 3.0)
        _seed_lines(opening)
        fields = _seed_lines(out)
        assert {f[4] for f in fields[5:]} == {b"CMDVEL"}
        right, left = mega.read("targetR"), mega.read("targetL")
        assert (right, left) == pytest.approx((3.468, 3.094), abs=1e-3)
        vel_l, vel_r = float(fields[-1][2]), float(fields[-1][3])
        assert 0.85 * right < vel_r <= right + 0.2 and 0.85 * left < vel_l <= left + 0.2
        assert mega.read("rejectedCount") == 0 and mega.read("tlmEnabled") == 0
        assert mega.read("faultFlags") == 0
