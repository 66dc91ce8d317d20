"""The MCAP of a run among walls with a lidar, as a ROS 2 user plays it: ``wcdrive sim
corridor_lidar --mcap run.mcap`` read back the way rosbag2's own storage reads it
(``rosbags.rosbag2.Reader`` opens the .mcap as rosbag2 storage; ``AnyReader``
deserialises every message), its records checked against what Jazzy's rosbag2 MCAP
writer puts in one (``rosbag2_storage_mcap/src/mcap_storage.cpp``, jazzy branch:
``create_topic`` and ``update_metadata``) and against rosbags' own rosbag2 writer, and
its contents against the run: ``/scan`` against distances to the corridor's walls
worked out by hand, ``/tf_static`` against the mount, ``/map`` against the map file."""

from __future__ import annotations

import contextlib
import io
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_typestore

from wcdrive.plant.rosmap import OCCUPIED, OccupancyGrid, load_map, save_map
from wcdrive.ros2.bridge import TOPICS
from wcdrive.sim import rosout, runner, scenario
from wcdrive.sim.scenario import BUNDLED
from wcdrive.tools.cli import main as wcdrive_main

CORRIDOR = BUNDLED / "worlds" / "hospital_corridor.yaml"
JAZZY = get_typestore(Stores.ROS2_JAZZY)
#: The S3's range noise: 10 mm (1 sigma); the bound used here, 4 sigma.
BOUND = 0.04


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _read(path: Path) -> dict[str, list]:
    by_topic: dict[str, list] = defaultdict(list)
    with AnyReader([path]) as reader:
        for conn, log_time, raw in reader.messages():
            by_topic[conn.topic].append((log_time * 1e-9, reader.deserialize(raw, conn.msgtype)))
    return by_topic


@pytest.fixture(scope="module")
def corridor(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, dict[str, list], Path]:
    out = tmp_path_factory.mktemp("bag") / "corridor.mcap"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        assert wcdrive_main(["sim", "corridor_lidar", "--json", "--no-plots", "--mcap", str(out)]) == 0
    return json.loads(buf.getvalue())[0], _read(out), out


# ---- read as rosbag2 reads it ---------------------------------------------------------
def test_rosbag2_storage_opens_it_with_every_topic_and_the_latched_qos(corridor) -> None:
    metrics, by_topic, path = corridor
    with Reader(path) as bag:
        topics = {c.topic: c for c in bag.connections}
        assert {t: c.msgtype for t, c in topics.items()} == TOPICS
        assert bag.message_count == sum(len(v) for v in by_topic.values())
        for topic, conn in topics.items():
            (profile,) = conn.ext.offered_qos_profiles
            latched = topic in ("/tf_static", "/map")
            assert profile.durability.name == ("TRANSIENT_LOCAL" if latched else "VOLATILE"), topic
            sensor = topic in ("/imu", "/scan")        # as the live node offers them: sensor data
            assert profile.reliability.name == ("BEST_EFFORT" if sensor else "RELIABLE"), topic
            assert profile.history.name == "KEEP_LAST"
            assert profile.depth == (1 if latched else 100 if topic == "/tf" else 5 if sensor else 10)
    assert set(by_topic) == set(TOPICS)                        # every message deserialised
    assert len(by_topic["/scan"]) == metrics["lidar_scans"] > 200


def test_the_records_are_those_jazzys_rosbag2_writes(corridor) -> None:
    """Profile ``ros2``; per type a ``ros2msg`` schema holding the type store's full
    definition; per topic a ``cdr`` channel whose metadata is ``offered_qos_profiles``
    and ``topic_type_hash`` (RIHS01) as ``create_topic`` writes them; and the
    ``rosbag2`` metadata record with ``serialized_metadata`` (``update_metadata``):
    version 9, the topics and their counts."""
    _, by_topic, path = corridor
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        header = reader.get_header()
        records = list(reader.iter_metadata())
    assert header.profile == "ros2"
    for schema in summary.schemas.values():
        assert schema.encoding == "ros2msg"
        assert schema.data.decode() == JAZZY.generate_msgdef(schema.name, ros_version=2)[0]
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr"
        assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}
        assert channel.metadata["topic_type_hash"] == JAZZY.hash_rihs01(schema.name)
        assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
    (record,) = records
    assert record.name == "rosbag2" and set(record.metadata) == {"serialized_metadata"}
    meta = yaml.safe_load(record.metadata["serialized_metadata"])
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap" and meta["ros_distro"] == "jazzy"
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    assert counts == {topic: len(msgs) for topic, msgs in by_topic.items()}
    assert meta["message_count"] == sum(counts.values())
    for t in meta["topics_with_message_count"]:
        qos = parse_qos(t["topic_metadata"]["offered_qos_profiles"])
        latched = t["topic_metadata"]["name"] in ("/map", "/tf_static")
        assert (qos[0].durability.name == "TRANSIENT_LOCAL") == latched


def test_its_layout_is_that_of_rosbags_own_rosbag2_writer(corridor, tmp_path: Path) -> None:
    """A bag of the same topics written by rosbags' rosbag2 writer (version 9, MCAP
    storage), an independent emulation of rosbag2's: the same schemas, QoS profiles of
    the same keys, and serialized metadata of the same keys (rosbags' writes no
    ``topic_type_hash`` in a channel's metadata; Jazzy's rosbag2 does, and so do we)."""
    _, _, path = corridor
    other = tmp_path / "rosbags_bag"
    with Writer(other, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        for topic, msgtype in TOPICS.items():
            bag.add_connection(topic, msgtype, typestore=JAZZY,
                               offered_qos_profiles=parse_qos(_channels(path)[topic]["offered_qos_profiles"]))
    (theirs,) = other.glob("*.mcap")
    mine_ch, their_ch = _channels(path), _channels(theirs)
    assert set(mine_ch) == set(their_ch)
    for topic in mine_ch:
        assert set(their_ch[topic]) <= set(mine_ch[topic])
        assert yaml.safe_load(their_ch[topic]["offered_qos_profiles"]) == \
            yaml.safe_load(mine_ch[topic]["offered_qos_profiles"])
    assert _schemas(path) == _schemas(theirs)
    mine, their = _meta(path), _meta(theirs)
    assert set(mine) == set(their)
    assert set(mine["topics_with_message_count"][0]["topic_metadata"]) == \
        set(their["topics_with_message_count"][0]["topic_metadata"])
    with Reader(other) as bag:                     # the directory bag with its metadata.yaml
        assert {c.topic for c in bag.connections} == set(TOPICS)


def _channels(path: Path) -> dict[str, dict[str, str]]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    return {c.topic: dict(c.metadata) for c in summary.channels.values()}


def _schemas(path: Path) -> dict[str, tuple[str, bytes]]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    return {s.name: (s.encoding, s.data) for s in summary.schemas.values()}


def _meta(path: Path) -> dict:
    with path.open("rb") as f:
        (record,) = list(make_reader(f).iter_metadata())
    return yaml.safe_load(record.metadata["serialized_metadata"])


# ---- the contents ---------------------------------------------------------------------
def test_every_topics_stamps_increase_and_are_the_log_times(corridor) -> None:
    _, by_topic, _ = corridor
    for topic, msgs in by_topic.items():
        times = np.array([t for t, _ in msgs])
        headers = [m.transforms[0].header if topic.startswith("/tf") else m.header for _, m in msgs]
        assert np.allclose([_stamp(h) for h in headers], times, atol=1e-9), topic
        if topic != "/diagnostics/serial":                    # lines of one tick share it
            assert np.all(np.diff(times) > 0), topic


def test_the_scans(corridor) -> None:
    """Constant beam count, the driver's fields, stamped at the first beam; the first
    scan (the chair at (1.0, 1.0) facing east, about to move: its mount puts the lidar
    at (1.20, 1.00)) against the corridor by hand: its walls at y = 0 and y = 2, its
    west end at x = 0: north and south 1.0 m, west 1.2 m, north-west sqrt(2) m."""
    _, by_topic, _ = corridor
    scans = [m for _, m in by_topic["/scan"]]
    assert {len(s.ranges) for s in scans} == {3240} == {len(s.intensities) for s in scans}
    assert {s.header.frame_id for s in scans} == {"laser"}
    first = scans[0]
    assert _stamp(first.header) == 0.0
    assert first.scan_time == pytest.approx(0.1) and first.time_increment == pytest.approx(0.1 / 3239)
    assert np.diff([_stamp(s.header) for s in scans]) == pytest.approx(0.1)
    assert first.angle_min == pytest.approx(-math.pi) and first.angle_max == pytest.approx(math.pi)
    assert first.range_min == pytest.approx(0.05) and first.range_max == pytest.approx(40.0)

    def beam(angle: float) -> float:
        return float(first.ranges[round((angle - first.angle_min) / first.angle_increment)])

    assert beam(math.pi / 2) == pytest.approx(1.0, abs=BOUND)
    assert beam(-math.pi / 2) == pytest.approx(1.0, abs=BOUND)
    assert beam(math.pi - 1e-6) == pytest.approx(1.2, abs=BOUND)
    assert beam(3 * math.pi / 4) == pytest.approx(math.sqrt(2.0), abs=BOUND)
    assert np.all(np.isfinite(first.ranges))                  # a closed corridor


def test_tf_static_is_the_mount_and_latched(corridor) -> None:
    _, by_topic, _ = corridor
    ((t, msg),) = by_topic["/tf_static"]
    (tf,) = msg.transforms
    assert t == 0.0 and tf.header.frame_id == "base_link" and tf.child_frame_id == "laser"
    tr, q = tf.transform.translation, tf.transform.rotation
    assert (tr.x, tr.y, tr.z) == pytest.approx((0.20, 0.0, 0.30))
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0.0, 0.0, 0.0, 1.0))


def test_the_map_round_trips(corridor, tmp_path: Path) -> None:
    """``/map`` is the world's map as map_server publishes it: loaded back (saved as
    map_saver saves it, then read as map_server reads it) it gives the same cells."""
    _, by_topic, _ = corridor
    ((t, msg),) = by_topic["/map"]
    grid = _grid(msg)
    expected = load_map(CORRIDOR)
    assert t == 0.0 and msg.header.frame_id == "map"
    assert np.array_equal(grid.data, expected.data)
    assert grid.resolution == pytest.approx(0.05) and grid.origin == pytest.approx(expected.origin)
    again = load_map(save_map(grid, tmp_path / "from_bag"))
    assert np.array_equal(again.data == OCCUPIED, expected.data == OCCUPIED)


def _grid(msg) -> OccupancyGrid:
    info = msg.info
    yaw = 2 * math.atan2(info.origin.orientation.z, info.origin.orientation.w)
    return OccupancyGrid(np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width),
                         float(info.resolution), (info.origin.position.x, info.origin.position.y, yaw))


def test_cmd_vel_is_stamped(corridor) -> None:
    _, by_topic, _ = corridor
    cmds = by_topic["/cmd_vel"]
    assert {m.header.frame_id for _, m in cmds} == {"base_link"}
    assert max(m.twist.linear.x for _, m in cmds) == pytest.approx(0.5, abs=1e-6)


# ---- a head-down lidar, in a hand-written room ----------------------------------------------
def test_a_head_down_lidar_in_the_furnished_room(tmp_path: Path) -> None:
    """The room with the lidar turned 90 deg and mounted head down (the driver not
    told): ``/tf_static`` has the yaw after the roll, and a beam's end put through it
    and the chair's true pose lands on the wall it saw; ``/map`` is the room drawn
    into 5 cm cells, and it round-trips through map_saver and map_server's files."""
    path = tmp_path / "room.toml"
    room = BUNDLED / "worlds" / "furnished_room.toml"
    path.write_text(f'settle_s = 0.0\n[world]\nfile = "{room}"\nstart = [4.0, 1.2, 30]\n'
                    '[lidar]\nmodel = "rplidar_s3"\nx = 0.3\ny = 0.1\nyaw_deg = 90\nroll_deg = 180\n'
                    "[[segment]]\nstop = true\nduration = 0.5\n")
    sc = scenario.load(str(path))
    result = runner.run(sc)
    out = tmp_path / "room.mcap"
    rosout.write_mcap(result, out, sc.params())
    by_topic = _read(out)
    ((_, msg),) = by_topic["/tf_static"]
    (tf,) = msg.transforms
    q, tr = tf.transform.rotation, tf.transform.translation
    c = math.sqrt(0.5)
    assert (q.x, q.y, q.z, q.w) == pytest.approx((c, c, 0.0, 0.0))       # Rz(90 deg) Rx(180 deg)
    rot = _matrix(q.x, q.y, q.z, q.w)
    x0, y0, th = sc.start
    world = sc.world
    ends = []
    for _, scan in by_topic["/scan"]:
        angles = scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment
        r = np.asarray(scan.ranges, dtype=float)
        laser = np.stack((r * np.cos(angles), r * np.sin(angles), np.zeros_like(r)))
        base = rot @ laser + np.array([[tr.x], [tr.y], [tr.z]])
        cm, sm = math.cos(th), math.sin(th)
        ends.append(np.stack((x0 + cm * base[0] - sm * base[1], y0 + sm * base[0] + cm * base[1]), axis=1))
    ends = np.concatenate(ends)
    # each beam's end on the geometry: its distance to the nearest wall, box side or circle
    gap = _distance_to_world(ends, world.segments, world.circles)
    assert np.mean(gap < BOUND) > 0.98
    ((_, grid_msg),) = by_topic["/map"]
    grid = _grid(grid_msg)
    assert grid.resolution == pytest.approx(0.05)
    for x0s, y0s, x1s, y1s in world.segments:                 # every wall's middle is occupied
        assert grid.value_at((x0s + x1s) / 2 + 1e-6, (y0s + y1s) / 2 + 1e-6) == OCCUPIED or \
            grid.value_at((x0s + x1s) / 2 - 1e-6, (y0s + y1s) / 2 - 1e-6) == OCCUPIED
    assert grid.value_at(4.0, 3.0) == 0                       # the middle of the room is free
    again = load_map(save_map(grid, tmp_path / "room_map"))
    assert np.array_equal(again.data, grid.data) and again.origin == pytest.approx(grid.origin)


def _matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _distance_to_world(points: np.ndarray, segments: np.ndarray, circles: np.ndarray) -> np.ndarray:
    a, b = segments[None, :, :2], segments[None, :, 2:]
    p = points[:, None, :]
    ab = b - a
    u = np.clip(np.sum((p - a) * ab, axis=2) / np.sum(ab * ab, axis=2), 0.0, 1.0)
    best = np.min(np.linalg.norm(p - (a + u[..., None] * ab), axis=2), axis=1)
    if len(circles):
        d = np.abs(np.linalg.norm(p - circles[None, :, :2], axis=2) - circles[None, :, 2])
        best = np.minimum(best, d.min(axis=1))
    return best
