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


def _speed(board: SimulatedBoard, window: float = 0.1) -> tuple[float, float]:
    """The chair's ground speed (m/s) over ``window`` s of the board's own time, and that
    time at the end: a loaded machine that starves the board's thread slows both alike."""
    x0, y0, _ = board.pose()
    t0 = board.time
    while board.time < t0 + window:
        time.sleep(0.01)
    x1, y1, _ = board.pose()
    t1 = board.time
    return math.hypot(x1 - x0, y1 - y0) / (t1 - t0), t1


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
        while _speed(board)[0] < 0.2:
            assert time.monotonic() < deadline, "the peer's /cmd_vel never drove the chair"
        assert min(_speed(board)[0] for _ in range(5)) > 0.2        # driving, steadily
        os.kill(bridge.pid, signal.SIGKILL)
        killed, start = board.time, board.pose()
        deadline = time.monotonic() + 10
        while (moving := _speed(board, 0.05))[0] > 0.005:
            assert time.monotonic() < deadline, "still moving 10 s after the bridge died"
        stopped_after = moving[1] - killed                           # board seconds
        print(f"stopped {stopped_after:.2f} s (board time) after SIGKILL")
        end = board.pose()
        assert peer.poll() is None                                   # /cmd_vel still flowing
        # the watchdog (500 ms), the emergency ramp and the 50 ms tick grid
        assert stopped_after < 1.2, stopped_after
        assert math.hypot(end[0] - start[0], end[1] - start[1]) < 0.4
        assert max(_speed(board, 0.2)[0] for _ in range(3)) < 0.005  # and stays stopped
    finally:
        for process in (peer, bridge):
            if process.poll() is None:
                process.kill()
            process.wait(timeout=10)
        pty.close()
        board.close()
