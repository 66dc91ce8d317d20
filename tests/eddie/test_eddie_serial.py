"""The simulated Eddie from outside: ``wceddie://`` through pyserial, ``wcdrive pty
--eddie``, and a client written the way Eddie's ROS drivers are (tests/
eddie_square_client.py) driving a square through the pty, its odometry against the
plant's ground truth (the bounds are docs/eddie.md's figures)."""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from wcdrive.tools.cli import eddie_pty

CLIENT = Path(__file__).resolve().parents[1] / "support" / "eddie_square_client.py"


def test_wceddie_url_answers_like_the_board() -> None:
    with serial.serial_for_url("wceddie://?speed=4", timeout=0.5) as port:
        port.write(b"VER\rdist\rGOSPD 1 2 3\r")
        time.sleep(0.2)
        assert port.read(200) == b"000C\r00000000 00000000\rERROR\r"
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("wceddie://?colour=red")


def test_wcdrive_pty_eddie_serves_a_board() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "wcdrive", "pty", "--eddie", "--speed", "4"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        path = proc.stdout.readline().strip()
        with serial.Serial(path, 115200, timeout=0.5) as port:
            port.write(b"HWVER\r")
            assert port.read_until(b"\r") == b"0001\r"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.mark.thorough       # 15 s; fast: the pty serves a board (above), the Eddie reaches goals (navigation)
def test_square_client_through_wcdrive_pty_eddie_odometry_matches_ground_truth() -> None:
    pty = subprocess.Popen([sys.executable, "-m", "wcdrive", "pty", "--eddie", "--speed", "2", "--seed", "3"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert pty.stdout is not None
        path = pty.stdout.readline().strip()
        out = subprocess.run([sys.executable, str(CLIENT), path, "--side", "1.0"],
                             capture_output=True, text=True, timeout=90, check=True)
        odo = json.loads(out.stdout)
    finally:
        pty.send_signal(signal.SIGINT)          # it prints the ground truth as it stops
        _, err = pty.communicate(timeout=10)
    found = re.search(r"ground truth x=(\S+) y=(\S+) heading=(\S+)", err)
    assert found, err
    x, y, th = (float(v) for v in found.groups())
    error = math.hypot(odo["x"] - x, odo["y"] - y)
    heading_error = abs(math.remainder(odo["theta"] - th, 2 * math.pi))
    print(f"square: odometry ({odo['x']:.3f}, {odo['y']:.3f}, {odo['theta']:.3f}) "
          f"truth ({x:.3f}, {y:.3f}, {th:.3f}): {error * 1000:.0f} mm, {math.degrees(heading_error):.1f} deg")
    assert math.hypot(*odo["corners"][1][:2]) > 1.2  # it went round: the far corner ...
    assert math.hypot(x, y) < 0.6                   # ... and back toward the start
    assert error < 0.05
    assert math.degrees(heading_error) < 3.0


def test_connect_eddie_device_path_drives_through_a_tty() -> None:
    """``eddie:///dev/...``: the real-board path (pyserial's posix port), here on the pty."""
    import wcdrive

    bridge = eddie_pty(speed=2.0)
    try:
        with wcdrive.connect(f"eddie://{bridge.path}") as bot:
            assert isinstance(bot, wcdrive.EddieRobot) and bot.firmware_version == "000C"
            for _ in range(10):
                bot.set_velocity(0.2, 0.0)
                time.sleep(0.1)
            samples = []
            bot.on_telemetry(samples.append)
            time.sleep(0.5)
            estimate = bot.odometry
            x = estimate.pose.x
        truth = bridge.board.pose()[0]              # type: ignore[attr-defined]
    finally:
        bridge.close()
    assert len(samples) >= 10                       # DIST/HEAD/SPD polled at >= 20 Hz
    assert samples[-1].mode == "eddie" and samples[-1].count_left > 0
    assert 0.2 < x and abs(x - truth) < 0.03
    assert estimate.pose_covariance[0, 0] > 0 and estimate.pose_covariance[1, 1] >= 0


def test_connect_eddie_to_a_silent_device_times_out() -> None:
    import os

    import wcdrive

    master, slave = os.openpty()
    try:
        start = time.monotonic()
        with pytest.raises(wcdrive.WcdriveTimeoutError, match="no reply to 'VER'"):
            wcdrive.connect(f"eddie://{os.ttyname(slave)}", boot_timeout=0.5)
        assert 0.5 < time.monotonic() - start < 2.0
    finally:
        os.close(master)
        os.close(slave)
