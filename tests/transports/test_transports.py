"""The simulated chair as a serial device: ``wcsim://`` through pyserial."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
import serial

import wcdrive
from wcdrive.protocol.codec import Feedback, LineDecoder


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
        for _ in range(3):                        # the ROS graph's first cmd_vel: at rest
            host.cmd_vel_callback(_twist(0.0, 0.0))
            time.sleep(0.005)
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
        port.write(b"x:0.000,t:0.000,")             # neutral first: the board drives after it
        time.sleep(0.02)
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
    from wcdrive.boards.sim_board import SimulatedBoard
    from wcdrive.transports.pty_bridge import PtyBridge

    with PtyBridge(SimulatedBoard(speed=10).start()) as bridge:
        port = serial.Serial(bridge.path, 115200, timeout=0.5)
        try:
            got = b""
            port.write(b"rp0.0,lp0.0,\n")            # neutral first, as the seed's hosts
            while got.count(b"ENC:") < 4:
                got += port.read(port.in_waiting or 1)
            deadline = time.monotonic() + 10
            while b"MODE:WHEEL" not in got and time.monotonic() < deadline:
                port.write(b"rp2.0,lp2.0,\n")
                got += port.read(port.in_waiting or 1)
            assert b"MODE:WHEEL" in got
        finally:
            port.close()


def test_unplug_is_detected_and_the_device_reopened(tmp_path) -> None:
    """A device path that vanishes (USB unplugged) and comes back (a fresh board, as
    a Mega resets on plug-in): commands fail clearly meanwhile, then all resumes."""
    from wcdrive.boards.sim_board import SimulatedBoard
    from wcdrive.transports.pty_bridge import PtyBridge

    link = tmp_path / "ttyWC0"
    first = PtyBridge(SimulatedBoard(speed=10).start(), link=link).start()
    chair = wcdrive.connect(str(link), reconnect_timeout=20)
    try:
        assert chair.protocol_version == 4
        first.close()                                   # unplugged
        deadline = time.monotonic() + 5
        while "LINK_LOST" not in chair.events and time.monotonic() < deadline:
            time.sleep(0.01)
        assert "LINK_LOST" in chair.events
        with pytest.raises(wcdrive.WcdriveConnectionError, match="lost"):
            chair.set_velocity(0.2, 0.0)
        second = PtyBridge(SimulatedBoard(speed=10).start(), link=link).start()   # plugged back
        try:
            deadline = time.monotonic() + 10
            while "RECONNECTED" not in chair.events and time.monotonic() < deadline:
                time.sleep(0.01)
            assert "RECONNECTED" in chair.events
            assert chair.wait_for_handshake(10) == 4
            assert chair.needs_neutral          # a fresh board: the program resumes with a neutral
            chair.wait_for_neutral()
            chair.set_wheels(1.0, 1.0)
            modes = set()
            deadline = time.monotonic() + 10
            while "WHEEL" not in modes and time.monotonic() < deadline:
                chair.set_wheels(1.0, 1.0)
                modes.add(chair.wait_for_telemetry().mode)
            assert "WHEEL" in modes
        finally:
            chair.close()
            second.close()
    finally:
        chair.close()


def test_pyserial_miniterm_opens_wcsim_without_importing_wcdrive() -> None:
    """``python -m serial.tools.miniterm wcsim://``: the installed .pth hook lets plain
    pyserial find the handler. Runs miniterm on a pty as a person would."""
    import os
    import subprocess
    import sys

    master, slave = os.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "serial.tools.miniterm", "wcsim://?speed=5", "115200"],
        stdin=slave, stdout=slave, stderr=slave, start_new_session=True, cwd="/")
    os.close(slave)
    seen = b""
    neutral_at: int | None = None
    try:
        deadline = time.monotonic() + 20
        while b"MODE:WHEEL" not in seen and time.monotonic() < deadline:
            ready = __import__("select").select([master], [], [], 0.2)[0]
            if ready:
                seen += os.read(master, 65536)
            if b"ENC:" in seen and neutral_at is None:
                os.write(master, b"rp0.0,lp0.0,")           # neutral first, as the seed's hosts
                neutral_at = seen.count(b"ENC:")
            elif neutral_at is not None and seen.count(b"ENC:") >= neutral_at + 4:
                os.write(master, b"rp1.0,lp1.0,")
        assert b"ENC:" in seen and b"MODE:WHEEL" in seen, seen[-500:]
        os.write(master, b"\x1d")                         # Ctrl-]: quit
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)


def test_plain_pyserial_finds_wcsim_in_a_fresh_interpreter() -> None:
    import subprocess
    import sys

    code = ("import serial, sys; p = serial.serial_for_url('wcsim://?speed=5', timeout=2); "
            "print(p.readline().decode().strip()); print('wcdrive' in sys.modules); p.close()")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd="/", check=True).stdout.split()
    assert out == ["BOOT:final_control,POWER_ON", "True"]


@pytest.mark.simavr
def test_wcavr_url_opens_the_firmware_in_simavr_driving_the_chair(elf) -> None:
    """``serial_for_url("wcavr://<elf>")``: the compiled firmware behind a pyserial port."""
    port = serial.serial_for_url(f"wcavr://{elf}?realtime=0", timeout=0.5)
    try:
        assert port.readline() == b"BOOT:final_control,POWER_ON\r\n"
        got = b""
        port.write(b"rp0.0,lp0.0,\n")                    # neutral first, as the seed's hosts
        while got.count(b"ENC:") < 4:
            got += port.read(port.in_waiting or 1)
        deadline = time.monotonic() + 20
        while b"MODE:WHEEL" not in got and time.monotonic() < deadline:
            port.write(b"rp2.0,lp2.0,")
            got += port.read(port.in_waiting or 1)
        assert b"MODE:WHEEL" in got
        more = got.count(b"ENC:") + 10
        while got.count(b"ENC:") < more and time.monotonic() < deadline:   # 0.5 s of its time
            port.write(b"rp2.0,lp2.0,")
            got += port.read(port.in_waiting or 1)
        assert port.board.pose()[0] > 0.0                 # the firmware drove the chair
    finally:
        port.close()
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("wcavr://?colour=red")
