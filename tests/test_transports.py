"""The simulated chair as a serial device: ``wcsim://`` through pyserial."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
import serial

import wcdrive  # noqa: F401  (registers wcsim://)
from wcdrive.codec import Feedback, LineDecoder


class SeedHost:
    """The seed's ``wc_control`` send code (guide, listing 10), unchanged but for the port."""

    def __init__(self, serial_port) -> None:
        self.serial_port = serial_port

    def cmd_vel_callback(self, msg):
        cmd_str = f"x:{msg.linear.x:.3f},t:{msg.angular.z:.3f},"
        self.serial_port.write(cmd_str.encode())


def _twist(v: float, w: float):
    return SimpleNamespace(linear=SimpleNamespace(x=v), angular=SimpleNamespace(z=w))


def test_seed_host_drives_the_simulated_chair() -> None:
    port = serial.serial_for_url("wcsim://?speed=20", timeout=0.5)
    try:
        host = SeedHost(port)
        decoder = LineDecoder()
        feedback = []
        for _ in range(60):                       # 10 Hz for 6 simulated s (0.3 s wall)
            host.cmd_vel_callback(_twist(0.5, 0.0))
            time.sleep(0.005)
            feedback += [m for m in decoder.feed(port.read(port.in_waiting)) if isinstance(m, Feedback)]
        x, y, _ = port.board.pose()
        assert x > 1.0 and abs(y) < 0.3
        assert feedback and feedback[-1].mode == "CMDVEL"
        assert feedback[-1].count_right > 10000 and feedback[-1].count_left < -10000
    finally:
        port.close()


def test_silence_stops_the_simulated_chair() -> None:
    with serial.serial_for_url("wcsim://?speed=20", timeout=0.2) as port:
        for _ in range(20):
            port.write(b"x:0.500,t:0.000,")
            time.sleep(0.005)
        time.sleep(0.3)                           # 6 simulated s of silence
        text = port.read(100000)
        assert b"EVT:WATCHDOG" in text
        assert port.board.loop.fw.state.pwmL == 0 and port.board.loop.fw.state.parked


def test_bad_url_options_are_clear() -> None:
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("wcsim://?colour=red")
    with pytest.raises(serial.SerialException, match="speed"):
        serial.serial_for_url("wcsim://?speed=0")


def test_simulated_chair_on_a_pty() -> None:
    from wcdrive.transports.pty_bridge import PtyBridge
    from wcdrive.transports.sim_board import SimulatedBoard

    with PtyBridge(SimulatedBoard(speed=10).start()) as bridge:
        port = serial.Serial(bridge.path, 115200, timeout=0.5)
        try:
            got = b""
            deadline = time.monotonic() + 10
            while b"MODE:WHEEL" not in got and time.monotonic() < deadline:
                port.write(b"rp2.0,lp2.0,\n")
                got += port.read(port.in_waiting or 1)
            assert b"MODE:WHEEL" in got
        finally:
            port.close()
