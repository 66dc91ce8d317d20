"""One ROS 2 topic table (``wcdrive.ros2.topics``): the MCAP writer, the Foxglove view
and the DDS node read it, and agree with it and with each other on what a stock ROS 2
client sees: each topic's type, the QoS its publisher offers and its header's frame.
A recording made from a run offers each topic with the QoS the live node offers it, so
``ros2 bag play`` of that recording stands in for the node."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from wcdrive.ros2 import bridge, topics
from wcdrive.ros2.dds import node as dds_node
from wcdrive.tools.cli import main as wcdrive_main


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run among walls with a lidar, recorded: every recorded topic but the EKF's."""
    out = tmp_path_factory.mktemp("table") / "corridor.mcap"
    with contextlib.redirect_stdout(io.StringIO()):
        assert wcdrive_main(["sim", "corridor_lidar", "--json", "--no-plots", "--mcap", str(out)]) == 0
    return out


def _profile(offered: str) -> tuple[bool, bool, int]:
    (first,) = yaml.safe_load(offered)
    return first["reliability"] == "reliable", first["durability"] == "transient_local", first["depth"]


def test_the_recording_offers_each_topic_as_the_table_says(recording: Path) -> None:
    with recording.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    seen = {}
    for channel in summary.channels.values():
        row = topics.by_name(channel.topic)
        assert row.recorded, channel.topic
        assert summary.schemas[channel.schema_id].name == row.msgtype, channel.topic
        p = row.profile
        assert _profile(channel.metadata["offered_qos_profiles"]) == (p.reliable, p.transient_local, p.depth)
        seen[channel.topic] = p
    assert {"/imu", "/scan", "/tf_static", "/map", "/odom"} <= set(seen)
    assert not seen["/imu"].reliable and not seen["/scan"].reliable       # sensor data, as live


def test_each_recorded_header_carries_the_tables_frame(recording: Path) -> None:
    frames: dict[str, str] = {}
    with AnyReader([recording]) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic not in frames:
                msg = reader.deserialize(raw, conn.msgtype)
                if hasattr(msg, "header"):
                    frames[conn.topic] = msg.header.frame_id
    checked = 0
    for name, frame in frames.items():
        row = topics.by_name(name)
        if row.frame is not None:
            assert frame == row.frame, (name, frame, row.frame)
            checked += 1
    assert checked >= 4, frames


def test_the_writers_read_the_table() -> None:
    recorded = {t.name: t for t in topics.TABLE if t.recorded}
    assert bridge.TOPICS == {n: t.msgtype for n, t in recorded.items()}
    assert {n: bridge.qos(n) for n in recorded} == {n: t.profile for n, t in recorded.items()}
    live = {t.name: t for t in dds_node.TOPICS}
    assert live == {t.name: t for t in topics.TABLE if t.direction is not None}
    assert bridge.imu(0.0, 0.0, 0.0)["header"]["frame_id"] == topics.by_name("/imu").frame


def test_the_dds_node_offers_the_tables_qos() -> None:
    """The DDS writers the node makes carry the table's QoS (read back from Cyclone)."""
    from cyclonedds.core import Policy

    from tests.ros2.conftest import IdleRobot as Idle
    from tests.ros2.conftest import fresh_domain
    from wcdrive.ros2.dds.graph import RosNode

    ros = RosNode("wcdrive", domain=fresh_domain())
    try:
        node = dds_node.ChairNode(Idle(), ros, dds_node.Options(sim_time=True, scan=Idle()),  # type: ignore[arg-type]
                                  imu=dds_node.ImuTap())
        for name in node.published:
            profile = topics.by_name(name).profile
            q = node._pub[name].writer.get_qos()
            reliable = isinstance(q[Policy.Reliability], Policy.Reliability.Reliable)
            durable = q[Policy.Durability] == Policy.Durability.TransientLocal
            assert (reliable, durable, q[Policy.History].depth) == (
                profile.reliable, profile.transient_local, profile.depth), name
            if topics.by_name(name).recorded:              # the recording offers the same
                assert bridge.qos(name) == profile
    finally:
        ros.close()


def test_the_dds_node_reads_with_the_tables_reader_qos() -> None:
    """``/cmd_vel`` is read best effort (``Topic.live``: the row's ``reader``), so that a
    best-effort writer matches; ``/estop`` and ``/estop_reset`` reliably; the recording
    still offers ``/cmd_vel`` as its publisher does (reliable)."""
    from cyclonedds.core import Policy

    from tests.ros2.conftest import IdleRobot as Idle
    from tests.ros2.conftest import fresh_domain
    from wcdrive.ros2.dds.graph import RosNode

    assert not topics.by_name("/cmd_vel").live.reliable
    assert bridge.qos("/cmd_vel") == topics.by_name("/cmd_vel").profile == topics.DEFAULT
    ros = RosNode("wcdrive", domain=fresh_domain())
    try:
        node = dds_node.ChairNode(Idle(), ros, dds_node.Options())  # type: ignore[arg-type]
        readers = {"/cmd_vel": node._cmd_reader, "/estop": node._estop_reader,
                   "/estop_reset": node._reset_reader}
        for name, reader in readers.items():
            profile = topics.by_name(name).live
            q = reader.get_qos()
            reliable = isinstance(q[Policy.Reliability], Policy.Reliability.Reliable)
            durable = q[Policy.Durability] == Policy.Durability.TransientLocal
            assert (reliable, durable, q[Policy.History].depth) == (
                profile.reliable, profile.transient_local, profile.depth), name
    finally:
        ros.close()
