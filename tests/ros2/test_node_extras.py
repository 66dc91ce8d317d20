"""What ``ChairNode`` serves beyond ``Robot`` (``wcdrive.host.robot``): a chair's e-stop
through the node latches and releases the chair's own, and ``/diagnostics`` carries the
chair's board (its URL as the hardware id, its line counts, its faults, its last
``TLM:`` line); the Eddie, which has neither, is named by its ``name`` and stopped by
``/estop``. The node publishes into a recording stand-in for the ROS graph and is not
started: each test calls what its loop calls."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import wcdrive
from tests.ros2.conftest import IdleRobot
from tests.support.pty_chair import until
from wcdrive.protocol.codec import LineStats
from wcdrive.ros2.dds import messages
from wcdrive.ros2.dds.node import ChairNode, Options


class _Graph:
    """What ``ChairNode`` asks of a ``RosNode``, keeping what is published."""

    name, namespace = "wcdrive", "/"

    def __init__(self) -> None:
        self.published: dict[str, list[Any]] = {}

    def publisher(self, topic: str, msgtype: str, profile: Any) -> SimpleNamespace:
        return SimpleNamespace(publish=self.published.setdefault(topic, []).append)

    def subscription(self, topic: str, msgtype: str, profile: Any) -> SimpleNamespace:
        return SimpleNamespace(take=lambda N: [])

    def close(self) -> None:
        pass


def _diagnostics(node: ChairNode) -> dict[str, dict[str, Any]]:
    """One ``/diagnostics`` message, as the loop publishes it each second: status name ->
    (level, message, hardware id, values)."""
    node._publish_diagnostics()
    message = node.ros.published["/diagnostics"][-1]             # type: ignore[attr-defined]
    return {s["name"]: {"level": s["level"], "message": s["message"], "hardware_id": s["hardware_id"],
                        "values": {v["key"]: v["value"] for v in s["values"]}} for s in message["status"]}


def test_a_chairs_estop_and_board_reach_the_node() -> None:
    """``sim://``: the node's ``estop()`` latches the chair's e-stop (the ``/estop``
    path), ``reset_estop()`` releases it; ``/diagnostics`` names the chair's URL and
    carries its line counts, its (no) faults and its TLM line."""
    with wcdrive.connect("sim://?speed=2") as chair:
        assert isinstance(chair, wcdrive.Wheelchair)
        node = ChairNode(chair, _Graph(), Options())           # type: ignore[arg-type]
        assert until(lambda: chair.status is not None)
        before = _diagnostics(node)
        assert {s["hardware_id"] for s in before.values()} == {chair.url}
        link = before["wcdrive: link"]["values"]
        assert link["link_ok"] == "True" and int(link["good"]) > 0
        assert {"bad_crc", "spliced", "lost"} <= set(link)
        assert before["wcdrive: faults"]["message"] == "none"
        assert before["wcdrive: faults"]["level"] == messages.OK
        assert "wcdrive: TLM" in before and "wcdrive: battery" in before
        assert before["wcdrive: e-stop"]["message"] == "released"

        node.estop()
        assert chair.estop_latched and node.estop_held and node._board_estop()
        latched = _diagnostics(node)["wcdrive: e-stop"]
        assert (latched["level"], latched["values"]) == (messages.ERROR, {"host": "True", "board": "True"})

        node.reset_estop()
        assert not chair.estop_latched and not node.estop_held and node.errors == []
        assert _diagnostics(node)["wcdrive: e-stop"]["message"] == "released"
        node.close()


class _FaultedBoard(IdleRobot):
    """A ``BoardHealthSurface`` stand-in: a board that latched two faults and has sent no
    TLM line."""

    url = "/dev/ttyACM0"
    link_stats = LineStats(good=120, bad_crc=2, spliced=1, lost=3)
    faults = ("ENC_STALL_L", "DRIVER_DEAD")
    status = None


def test_a_boards_latched_faults_are_an_error_in_diagnostics() -> None:
    diagnostics = _diagnostics(ChairNode(_FaultedBoard(), _Graph(), Options()))  # type: ignore[arg-type]
    faults = diagnostics["wcdrive: faults"]
    assert (faults["level"], faults["message"]) == (messages.ERROR, "ENC_STALL_L, DRIVER_DEAD")
    assert faults["hardware_id"] == "/dev/ttyACM0"
    assert diagnostics["wcdrive: link"]["values"] == {"link_ok": "True", "good": "120", "bad_crc": "2",
                                                      "spliced": "1", "lost": "3"}
    assert "wcdrive: TLM" not in diagnostics                    # no TLM line yet


def test_the_eddies_diagnostics_name_it_and_estop_stops_it() -> None:
    """``eddie+sim://``: no board reports, so the link status carries ``link_ok`` alone,
    no faults and no TLM; the hardware id is the Eddie's ``name``. It has no latched
    e-stop: the node's ``estop()`` stops it and holds the node's own latch."""
    eddie = wcdrive.connect("eddie+sim://")
    try:
        assert isinstance(eddie, wcdrive.EddieRobot)
        node = ChairNode(eddie, _Graph(), Options())           # type: ignore[arg-type]
        diagnostics = _diagnostics(node)
        assert eddie.name and {s["hardware_id"] for s in diagnostics.values()} == {eddie.name}
        assert diagnostics["wcdrive: link"]["values"] == {"link_ok": str(eddie.link_ok)}
        assert diagnostics["wcdrive: faults"]["message"] == "none"
        assert not any(name in diagnostics for name in ("wcdrive: TLM", "wcdrive: battery"))
        node.estop()
        assert node.estop_held and node.errors == []
        latched = _diagnostics(node)["wcdrive: e-stop"]
        assert latched["values"] == {"host": "True", "board": "False"}
        node.reset_estop()
        assert not node.estop_held
        node.close()
    finally:
        eddie.close()
