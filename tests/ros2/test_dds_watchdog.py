"""The chair stops when the bridge dies: the bridge (``wcdrive ros2``) in a process of
its own drives a simulated board behind a pty, fed by the peer's 20 Hz ``/cmd_vel``;
SIGKILL the bridge (no cleanup runs, no stop is sent) and the board's watchdog stops
the chair 500 ms after the last command, while the peer keeps publishing.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.ros2.conftest import PEER, fresh_domain
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.transports.pty_bridge import PtyBridge

REPO = Path(__file__).resolve().parents[2]


def _speed(board: SimulatedBoard, dt: float = 0.1) -> float:
    x0, y0, _ = board.pose()
    time.sleep(dt)
    x1, y1, _ = board.pose()
    return math.hypot(x1 - x0, y1 - y0) / dt


def test_killing_the_bridge_stops_the_chair() -> None:
    board = SimulatedBoard(speed=1.0)
    pty = PtyBridge(board.start(), on_open=board.dtr).start()
    domain = fresh_domain()
    bridge = subprocess.Popen([sys.executable, "-m", "wcdrive", "ros2", "--url", pty.path,
                               "--domain", str(domain)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, cwd=REPO)
    peer = subprocess.Popen([sys.executable, str(PEER), "--domain", str(domain), "--mode", "forward",
                             "--seconds", "40"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert bridge.stdout is not None
        line = bridge.stdout.readline()                  # after connect: the node is up
        assert "wcdrive ros2: node /wcdrive" in line, (line, bridge.stderr.read() if bridge.stderr else "")
        deadline = time.monotonic() + 30
        while _speed(board) < 0.2:
            assert time.monotonic() < deadline, "the peer's /cmd_vel never drove the chair"
        assert min(_speed(board) for _ in range(5)) > 0.2           # driving, steadily
        os.kill(bridge.pid, signal.SIGKILL)
        killed, start = time.monotonic(), board.pose()
        while _speed(board, 0.05) > 0.005:
            assert time.monotonic() - killed < 3.0, "still moving 3 s after the bridge died"
        stopped_after = time.monotonic() - killed
        print(f"stopped {stopped_after:.2f} s after SIGKILL")
        end = board.pose()
        assert peer.poll() is None                                   # /cmd_vel still flowing
        # the watchdog (500 ms) and the emergency ramp, with room for a loaded machine
        assert stopped_after < 2.0, stopped_after
        assert math.hypot(end[0] - start[0], end[1] - start[1]) < 0.5
        assert min(_speed(board) for _ in range(5)) < 0.005          # and stays stopped
    finally:
        for process in (peer, bridge):
            if process.poll() is None:
                process.kill()
            process.wait(timeout=10)
        pty.close()
        board.close()
