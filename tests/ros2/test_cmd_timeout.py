"""The bridge's command timeout (docs/ros2.md, "Safety"): one ``/cmd_vel`` drives the
chair, its command resent every RESEND (0.1 s) while it is fresh, and ``cmd_timeout``
(0.5 s by default) after it arrived the chair is stopped, whatever the publisher does
next. ``ChairNode``'s own control loop on a graph that is a stand-in (its readers and
writers lists), the robot recording what it is told, the wall clock as the loop's."""

from __future__ import annotations

import threading
import time
from itertools import pairwise
from types import SimpleNamespace
from typing import Any

from tests.ros2.conftest import IdleRobot
from wcdrive.ros2.dds import types
from wcdrive.ros2.dds.node import RESEND, TWIST_STAMPED, ChairNode, Options


class _Reader:
    def __init__(self) -> None:
        self.queue: list[Any] = []
        self.lock = threading.Lock()

    def take(self, N: int) -> list[Any]:      # cyclonedds' name
        with self.lock:
            out, self.queue = self.queue[:N], self.queue[N:]
        return out


class _Graph:
    """What ``ChairNode`` asks of a ``RosNode``: publishers that keep nothing, readers
    the test fills."""

    name, namespace = "wcdrive", "/"

    def __init__(self) -> None:
        self.readers: dict[str, _Reader] = {}

    def publisher(self, topic: str, msgtype: str, profile: object) -> SimpleNamespace:
        return SimpleNamespace(publish=lambda message: None)

    def subscription(self, topic: str, msgtype: str, profile: object) -> _Reader:
        self.readers[topic] = _Reader()
        return self.readers[topic]

    def close(self) -> None:
        pass


class _Chair(IdleRobot):
    """Records each command with the monotonic time it came."""

    command_limits = (2.68, 9.4)

    def __init__(self) -> None:
        self.calls: list[tuple[float, str, tuple[float, ...]]] = []

    def on_telemetry(self, callback: object) -> None:
        pass

    def set_velocity(self, linear: float, angular: float) -> None:
        self.calls.append((time.monotonic(), "drive", (linear, angular)))

    def stop(self) -> None:
        self.calls.append((time.monotonic(), "stop", ()))


def _command(node: ChairNode, linear: float, angular: float) -> float:
    """Puts a ``TwistStamped`` on the node's ``/cmd_vel`` reader, stamped now; returns the
    monotonic time it was there."""
    stamp = node.now()
    message = types.build(TWIST_STAMPED, {
        "header": {"stamp": {"sec": int(stamp), "nanosec": int((stamp % 1) * 1e9)}, "frame_id": ""},
        "twist": {"linear": {"x": linear, "y": 0.0, "z": 0.0},
                  "angular": {"x": 0.0, "y": 0.0, "z": angular}}})
    message.sample_info = SimpleNamespace(valid_data=True)
    reader = node.ros.readers[node.topic_names["/cmd_vel"]]        # type: ignore[attr-defined]
    with reader.lock:
        reader.queue.append(message)
    return time.monotonic()


def test_one_command_is_resent_until_the_timeout_then_the_chair_stops() -> None:
    """One command of 0.2 m/s at t0, nothing after: driving calls from t0 every 0.1 s
    (the resends), none from 0.6 s after t0, and a stop 0.5 to 0.75 s after it. Red
    with the timeout ignored: the chair drives on to the end."""
    chair, graph = _Chair(), _Graph()
    options = Options()
    assert options.cmd_timeout == 0.5
    node = ChairNode(chair, graph, options).start()           # type: ignore[arg-type]
    try:
        _command(node, 0.0, 0.0)                               # the message type built
        time.sleep(0.3)
        chair.calls.clear()
        t0 = _command(node, 0.2, 0.0)
        time.sleep(1.0)
    finally:
        node.close()
    drives = [t - t0 for t, kind, _ in chair.calls if kind == "drive"]
    stops = [t - t0 for t, kind, _ in chair.calls if kind == "stop"]
    # the loop's 20 ms period, and slack for a loaded machine's scheduling (a test run
    # on two workers): the timeout ignored, the chair would drive on to 1 s
    assert len(drives) >= 3 and drives[0] < 0.15, drives
    assert max(drives) < options.cmd_timeout + 0.1, drives
    gaps = [b - a for a, b in pairwise(drives)]
    assert max(gaps) <= RESEND + 0.1, gaps
    assert stops and options.cmd_timeout <= stops[0] < options.cmd_timeout + 0.25, stops
    assert chair.calls[-1][1] == "stop"


def test_a_command_past_the_chairs_limits_is_dropped_and_never_drives() -> None:
    """The gate the bridge builds from the chair's limits (2.68 m/s, 9.4 rad/s): 2.7 m/s
    and 9.5 rad/s are dropped, counted, and never reach the chair; 2.6 m/s drives."""
    chair, graph = _Chair(), _Graph()
    node = ChairNode(chair, graph, Options()).start()          # type: ignore[arg-type]
    try:
        time.sleep(0.2)
        chair.calls.clear()
        _command(node, 2.7, 0.0)
        _command(node, 0.0, 9.5)
        time.sleep(0.2)
        refused = [c for c in chair.calls if c[1] == "drive"]
        _command(node, 2.6, 0.0)
        time.sleep(0.2)
    finally:
        node.close()
    assert refused == []
    assert node.gate.counts["out_of_range"] == 2 and node.gate.counts["accepted"] == 1
    assert any(kind == "drive" and args[0] > 0.0 for _, kind, args in chair.calls)
