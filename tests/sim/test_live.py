"""``wcdrive sim --live``: a WebSocket client speaking Foxglove's protocol
subscribes to ``/odom`` and receives typed (CDR, ros2msg schema) odometry messages;
on a scenario with a world and a lidar, to ``/scan`` and ``/map``: what Foxglove's 3D
panel draws (the scan, the map and the chair's transforms)."""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import socket
import struct
import threading
from pathlib import Path

import websockets
from rosbags.typesys import Stores, get_typestore

from wcdrive.tools.cli import main as wcdrive_main

SCENARIO = """
name = "live_short"
description = "2 s forward"
settle_s = 0.5
[[segment]]
cmdvel = [0.4, 0.0]
duration = 2.0
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _receive_odom(port: int, want: int, topic: str = "/odom") -> tuple[dict, list[tuple[int, bytes]]]:
    uri = f"ws://127.0.0.1:{port}"
    for _ in range(200):                                     # the server starts after the run
        try:
            ws = await websockets.connect(uri, subprotocols=["foxglove.sdk.v1"])  # type: ignore[list-item]
            break
        except OSError:
            await asyncio.sleep(0.05)
    else:
        raise AssertionError("no server")
    got: list[tuple[int, bytes]] = []
    log: list = []
    channel: dict = {}
    async with ws:
        while len(got) < want:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=10)
            except websockets.ConnectionClosed as exc:
                raise AssertionError(f"closed after {len(got)} messages, channel {channel}, "
                                     f"log {log}") from exc
            log.append(frame[:80] if isinstance(frame, str) else bytes(frame[:1]))
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise" and not channel:
                    odom = [c for c in msg["channels"] if c["topic"] == topic]
                    if odom:
                        channel = odom[0]
                        await ws.send(json.dumps({"op": "subscribe",
                                                  "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
            elif frame[0] == 0x01:                            # MessageData
                sub, log_time = struct.unpack_from("<IQ", frame, 1)
                assert sub == 7
                got.append((log_time, bytes(frame[13:])))
    return channel, got


def test_a_websocket_client_receives_odom(tmp_path: Path) -> None:
    toml = tmp_path / "live_short.toml"
    toml.write_text(SCENARIO)
    port = _free_port()
    out = io.StringIO()

    def serve() -> None:
        with contextlib.redirect_stdout(out):
            wcdrive_main(["sim", str(toml), "--live", "--live-port", str(port), "--no-plots", "--json"])

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    channel, got = asyncio.run(_receive_odom(port, want=10))
    thread.join(timeout=10)
    assert channel["schemaName"] == "nav_msgs/msg/Odometry"
    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs = [store.deserialize_cdr(data, "nav_msgs/msg/Odometry") for _, data in got]
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert [t for t, _ in got] == [round(s * 1e9) for s in stamps]     # log time = board clock
    assert all(m.child_frame_id == "base_link" for m in msgs)
    assert msgs[-1].pose.pose.position.x > msgs[0].pose.pose.position.x    # it drives forward


LIDAR_SCENARIO = """
name = "live_lidar"
settle_s = 0.5
[world]
walls = [[3.0, -2.0, 3.0, 2.0, -1.0, 2.0, -1.0, -2.0, 3.0, -2.0]]
[lidar]
model = "rplidar_s3"
[[segment]]
cmdvel = [0.3, 0.0]
duration = 2.0
"""


def _serve(tmp_path: Path, text: str, port: int) -> threading.Thread:
    toml = tmp_path / "live.toml"
    toml.write_text(text)

    def serve() -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            wcdrive_main(["sim", str(toml), "--live", "--live-port", str(port), "--no-plots", "--json"])

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return thread


def test_a_websocket_client_receives_the_scans(tmp_path: Path) -> None:
    """The S3's scans of a 4 m x 4 m box, the chair 3 m from its east wall: 3,240 beams
    in frame ``laser``, the beam ahead 3 - 0.20 m at the start."""
    port = _free_port()
    thread = _serve(tmp_path, LIDAR_SCENARIO, port)
    channel, got = asyncio.run(_receive_odom(port, want=5, topic="/scan"))
    thread.join(timeout=10)
    assert channel["schemaName"] == "sensor_msgs/msg/LaserScan"
    store = get_typestore(Stores.ROS2_HUMBLE)
    scans = [store.deserialize_cdr(data, "sensor_msgs/msg/LaserScan") for _, data in got]
    assert all(len(m.ranges) == 3240 and m.header.frame_id == "laser" for m in scans)
    first = scans[0]
    ahead = float(first.ranges[round((0.0 - first.angle_min) / first.angle_increment)])
    assert abs(ahead - 2.8) < 0.1, ahead


def test_a_client_that_connects_late_still_gets_the_map_and_the_laser_frame(tmp_path: Path) -> None:
    """``/map`` and ``/tf_static`` go out at 0 s, before any client can be connected; a
    live view has no latching, so they are sent again each second of the run."""
    port = _free_port()
    thread = _serve(tmp_path, LIDAR_SCENARIO, port)
    channel, got = asyncio.run(_receive_odom(port, want=1, topic="/map"))
    _, statics = asyncio.run(_receive_odom(port, want=1, topic="/tf_static"))
    thread.join(timeout=10)
    store = get_typestore(Stores.ROS2_HUMBLE)
    grid = store.deserialize_cdr(got[0][1], "nav_msgs/msg/OccupancyGrid")
    assert channel["schemaName"] == "nav_msgs/msg/OccupancyGrid" and grid.header.frame_id == "map"
    assert (grid.data == 100).any() and (grid.data == 0).any()          # walls and floor
    tf = store.deserialize_cdr(statics[0][1], "tf2_msgs/msg/TFMessage")
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [("base_link", "laser")]
