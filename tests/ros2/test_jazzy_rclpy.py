"""The bridge against a stock ROS 2 Jazzy client: rclpy 7.1 on ``rmw_fastrtps_cpp``
(Fast DDS 2.14, Jazzy's default middleware) from the package index's ``ros-jazzy-*``
wheels, in a Python 3.12 venv built once per machine (``jazzy_env.py``; the session
fixture ``jazzy_python``). The client (``jazzy_client.py``) sees the bridge only
through rclpy; ``jazzy_stage.py`` runs it, in a network namespace of its own when
``unshare -rn`` works (Jazzy's default discovery range multicasts; there that stays
inside the namespace). One run, one test (so that pytest-xdist never runs it twice),
and each check a function of ``CHECKS``, all of them run and every failure named:

- node ``/wcdrive`` is listed, found by a client on Jazzy's default discovery range
  (SUBNET) started after the bridge;
- each topic's type, RIHS01 hash (equal to the stock package's own) and QoS as
  ``get_publishers_info_by_topic`` / ``get_subscriptions_info_by_topic`` give them,
  against the topic table (``wcdrive.ros2.topics``); no incompatible-QoS event on any
  endpoint the client makes;
- ``/odom``, ``/scan`` (3,240 beams), ``/imu``, ``/tf``, ``/tf_static`` arrive;
- a BEST_EFFORT and a RELIABLE TwistStamped writer each drive the chair; ``/estop``
  stops it under a continuing stream, ``/estop_reset`` releases it;
- after SIGTERM the bridge's node, endpoints and matches leave the client's graph
  within 1 s;
- a stack replica: the bridge configured from a ``diff_drive_controller`` YAML and
  ``-r __node:=wheelchair_controller``; a BEST_EFFORT TwistStamped writer on
  ``/wheelchair_controller/cmd_vel`` drives it within the YAML's speed limit, an
  EKF-style reader gets ``/wheelchair_controller/odom``, and the bridge publishes no
  ``/tf`` and no ``/tf_static`` (the stack's EKF and robot_state_publisher own them);
  a sensor-data scan reader sees a wall at its known bearing through the stack's
  lidar mount (head down, facing back, ``rplidar_ros`` told ``inverted``), set by the
  YAML's ``lidar_*`` parameters;
- four late joiners (LOCALHOST, ``ROS_STATIC_PEERS``, SUBNET, ``ROS_LOCALHOST_ONLY``),
  started more than 30 s after a bridge (Cyclone's default pruning of unanswered
  peer addresses), each find it and its ``/odom`` within a few seconds.
"""

from __future__ import annotations

import json
import math
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.ros2.conftest import fresh_domain
from wcdrive.ros2 import topics
from wcdrive.ros2.dds import config, types

REPO = Path(__file__).resolve().parents[2]
NETNS = ("ip link set lo up && ip link add wa type veth peer name wb && "
         "ip addr add 198.51.100.1/24 dev wa && ip link set wa up && ip link set wb up && ")
#: The late joiners start this long after their bridge: past Cyclone's default 30 s.
LATE_S = 32.0
#: "Within a few seconds": a late joiner must see the bridge and its /odom by then.
FOUND_WITHIN_S = 5.0
#: The bridge's endpoints must leave a stock node's graph this soon after SIGTERM.
LEAVE_WITHIN_S = 1.0
#: The topics of the bridge under test (``sim://`` with a lidar, no sim time).
LIVE = [t for t in topics.TABLE if t.direction is not None and t.name != "/clock"]


def _netns() -> bool:
    return bool(shutil.which("unshare") and shutil.which("ip")) and subprocess.run(
        ["unshare", "-rn", "sh", "-c", NETNS + "true"], capture_output=True).returncode == 0


def stage(jazzy_python: Path, world: Path) -> dict[str, Any]:
    """``jazzy_stage.py``'s run (in a network namespace when it can): the main client's
    JSON, the late joiners', the bridges' exit codes."""
    world.write_text("walls = [[5.0, -3.0, 5.0, 3.0]]\n")          # 5 m ahead: room to drive
    run = [sys.executable, "-m", "tests.ros2.jazzy_stage", "--python", str(jazzy_python),
           "--domains", f"{fresh_domain()},{fresh_domain()},{fresh_domain()}", "--world", str(world),
           "--late", str(LATE_S)]
    netns = _netns()
    command = ["unshare", "-rn", "sh", "-c", NETNS + "exec " + shlex.join(run)] if netns else run
    out = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr[-4000:]
    result = dict(json.loads(out.stdout.strip().splitlines()[-1]))
    result["netns"] = netns
    return result


# ---- what is checked on the run, one function each (all run, every failure named) -------
CHECKS: list[Callable[[dict[str, Any]], None]] = []


def check(function: Callable[[dict[str, Any]], None]) -> Callable[[dict[str, Any]], None]:
    CHECKS.append(function)
    return function


@check
def a_stock_node_on_the_default_range_lists_the_bridge(run: dict[str, Any]) -> None:
    main = run["main"]
    assert main["rmw"] == "rmw_fastrtps_cpp"
    assert main["discovered_s"] is not None and main["discovered_s"] < 10.0, main["discovered_s"]
    assert "/wcdrive" in main["node_names"], main["node_names"]


@check
def types_hashes_and_qos_as_rclpy_sees_them(run: dict[str, Any]) -> None:
    table = run["main"]["table"]
    assert sorted(table) == sorted(t.name for t in LIVE), sorted(table)
    for row in LIVE:
        (seen,) = table[row.name]
        p = row.live
        assert seen["dir"] == row.direction and seen["type"] == row.msgtype, (row.name, seen)
        assert seen["hash"] == seen["stock_hash"] == types.type_hash(row.msgtype), (row.name, seen)
        assert seen["reliability"] == ("reliable" if p.reliable else "best_effort"), (row.name, seen)
        durability = "transient_local" if p.transient_local else "volatile"
        assert seen["durability"] == durability, (row.name, seen)
        assert seen["depth"] in (0, p.depth), (row.name, seen)   # DDS discovery carries no depth


@check
def a_stack_replica_takes_the_bridge_in_place_of_its_drive(run: dict[str, Any]) -> None:
    from tests.ros2.jazzy_stage import CONTROLLER, REPLICA_LIMIT_MPS

    replica = run["replica"]
    assert "error" not in replica, replica
    assert replica["node_listed"] is not None, replica
    assert replica["matched_s"] is not None, replica          # the BEST_EFFORT writer matched
    odom, cmd = (replica["endpoints"][f"/{CONTROLLER}/{t}"] for t in ("odom", "cmd_vel"))
    assert [e["dir"] for e in odom] == ["pub"] and [e["dir"] for e in cmd] == ["sub"], replica
    # asked for 0.3 m/s for 4 s under the YAML's 0.2 m/s limit: it drives, up to the limit
    assert replica["moved_m"] is not None and 0.2 < replica["moved_m"] < 4.0 * REPLICA_LIMIT_MPS, replica
    assert 0.75 * REPLICA_LIMIT_MPS < replica["top_speed_mps"] <= REPLICA_LIMIT_MPS + 0.02, replica
    assert replica["tf_publishers"] == {"/tf": [], "/tf_static": []}, replica
    assert replica["incompatible_qos"] == [], replica


@check
def the_stacks_scan_reader_sees_the_walls_through_the_inverted_backward_mount(run: dict[str, Any]) -> None:
    """The replica's lidar (``REPLICA_YAML``: head down, facing back, 0.30 m behind the
    axle; ``rplidar_ros`` told ``inverted``) among ``REPLICA_WALLS``, the chair
    standing at the origin. Worked by hand: the laser frame is the URDF joint's yaw pi
    with no roll left (the driver, told, undoes the head-down mirror), so a return at
    stated angle ``a`` and range ``r`` is the point ``(-0.30 + r cos(pi + a), r sin(pi +
    a))`` of base_link; put there, the returns lie on the walls (95 % within 6 cm: the
    S3's 1 cm noise and rplidar_ros's stated angles up to 1 degree off; the slots past
    a wall's end repeat its last return), the wall on the left among them. A mount
    facing forward puts them 5 m behind the chair, a mirrored scan the left wall on
    the right. rplidar_ros states its span as ``pi - 359 deg .. pi`` over the S3's
    3,240 slots, its ``range_min`` is 0.15 m, and the S3's dense returns give
    intensity 47 (0 where no return came)."""
    from tests.ros2.jazzy_stage import REPLICA_MOUNT, REPLICA_WALLS

    scan = run["replica"].get("scan")
    assert scan is not None, run["replica"]
    assert scan["frame_id"] == "laser" and scan["beams"] == 3240, {k: scan[k] for k in scan if k != "returns"}
    assert scan["angle_max"] == pytest.approx(math.pi, abs=1e-6), scan["angle_max"]
    assert scan["angle_min"] == pytest.approx(math.pi - math.radians(359.0), abs=1e-6), scan["angle_min"]
    assert scan["range_min"] == pytest.approx(0.15), scan["range_min"]
    assert scan["intensities"] == [0.0, 47.0], scan["intensities"]
    mount_x, yaw = REPLICA_MOUNT[0], REPLICA_MOUNT[5]
    points = [(mount_x + r * math.cos(yaw + a), r * math.sin(yaw + a)) for a, r in scan["returns"]]
    off = sorted(min(_to_segment(p, w) for w in REPLICA_WALLS) for p in points)
    assert len(points) > 500 and off[int(0.95 * len(off))] < 0.06, (len(points), off[-20:])
    on_the_left = sum(_to_segment(p, REPLICA_WALLS[1]) < 0.06 for p in points)
    assert on_the_left > 100, on_the_left


def _to_segment(point: tuple[float, float], wall: list[float]) -> float:
    """The distance (m) from ``point`` to the wall ``[x0, y0, x1, y1]``."""
    (px, py), (x0, y0, x1, y1) = point, wall
    dx, dy = x1 - x0, y1 - y0
    t = max(0.0, min(1.0, ((px - x0) * dx + (py - y0) * dy) / (dx * dx + dy * dy)))
    return math.hypot(px - x0 - t * dx, py - y0 - t * dy)


@check
def no_incompatible_qos_event(run: dict[str, Any]) -> None:
    assert run["main"]["incompatible_qos"] == []
    for name, probe in run["discovery"].items():
        assert probe.get("incompatible_qos") == [], (name, probe)


@check
def odom_scan_imu_and_tf_arrive(run: dict[str, Any]) -> None:
    from wcdrive.plant.lidar import RPLIDAR_S3

    data = run["main"]["data"]
    for name in ("/odom", "/scan", "/imu", "/tf", "/joint_states"):
        assert data[name]["count"] > 0, (name, data[name])
        if topics.by_name(name).frame is not None:
            assert data[name]["frame_id"] == topics.by_name(name).frame, (name, data[name])
    assert data["/odom"]["stamp_rate_hz"] > 15.0, data["/odom"]         # 20 Hz
    assert 7.0 < data["/scan"]["stamp_rate_hz"] < 13.0, data["/scan"]    # 10 Hz
    assert data["/scan"]["beams"] == RPLIDAR_S3.beams, data["/scan"]
    assert data["/imu"]["count"] > 100, data["/imu"]                     # 400 Hz, best effort
    assert ["odom", "base_link"] in data["/tf"]["frames"], data["/tf"]
    statics = data["/tf_static"]["frames"]                               # transient local: a late reader
    assert ["base_link", "imu_link"] in statics, statics
    assert any(child == topics.by_name("/scan").frame for _, child in statics), statics


@check
def a_best_effort_and_a_reliable_twist_stamped_writer_each_drive_the_chair(run: dict[str, Any]) -> None:
    """0.3 m/s for 2 s from a writer of each reliability, alone on /cmd_vel."""
    for writer in ("best_effort", "reliable"):
        drive = run["main"]["drive"][writer]
        assert drive["matched_s"] is not None, (writer, drive)     # the bridge's reader matched it
        assert drive["moved_m"] > 0.15 and drive["speed"] > 0.15, (writer, drive)


@check
def estop_stops_the_chair_and_estop_reset_releases_it(run: dict[str, Any]) -> None:
    estop = run["main"]["estop"]
    assert estop["speed_before"] > 0.15, estop
    assert estop["speed_held"] < 0.01 and abs(estop["moved_held_m"]) < 0.01, estop   # stream goes on
    assert estop["speed_after_reset"] > 0.15, estop


@check
def after_sigterm_the_endpoints_leave_the_graph_within_1s(run: dict[str, Any]) -> None:
    leave = run["main"]["leave"]
    assert leave["all_gone_s"] is not None and leave["all_gone_s"] <= LEAVE_WITHIN_S, leave
    assert run["bridge_exit"] == 143, (run["bridge_exit"], run.get("bridge_stderr"))


@check
def late_nodes_find_the_bridge_in_every_discovery_setting(run: dict[str, Any]) -> None:
    assert run["late_s"] >= LATE_S - 0.5, run["late_s"]
    settings = ("SUBNET", "LOCALHOST", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY")
    assert sorted(run["discovery"]) == sorted(settings), sorted(run["discovery"])
    for setting, probe in run["discovery"].items():
        assert probe.get("node_s") is not None and probe["node_s"] <= FOUND_WITHIN_S, (setting, probe)
        assert probe.get("odom_s") is not None and probe["odom_s"] <= FOUND_WITHIN_S, (setting, probe)


def test_the_bridge_under_a_stock_jazzy_rclpy(jazzy_python: Path, tmp_path: Path) -> None:
    """One run (``stage``), every check of ``CHECKS`` on it; one test, so that
    pytest-xdist never runs it twice. Prints the times it measured."""
    run = stage(jazzy_python, tmp_path / "wall.toml")
    main = run["main"]
    assert "error" not in main, main
    print(json.dumps({k: v for k, v in main.items() if k not in ("table", "data")}))
    print(f"after SIGTERM, gone from the graph in (s): {main.get('leave')}")
    print(f"stack replica: {run.get('replica')}")
    for setting, probe in run.get("discovery", {}).items():
        print(f"{setting}: started {run.get('late_s')} s after the bridge, listed it in "
              f"{probe.get('node_s')} s, first /odom in {probe.get('odom_s')} s")
    failures = []
    for function in CHECKS:
        try:
            function(run)
        except (AssertionError, KeyError, TypeError) as exc:
            failures.append(f"{function.__name__}: {type(exc).__name__} {exc}")
    assert not failures, "\n".join(failures)


def test_the_configuration_carries_both_fast_dds_fixes() -> None:
    """Key hashes on disposals (Fast DDS drops the endpoints at once) and an SPDP
    announcement to every peer address every second, never pruned."""
    for xml in (config.xml(), config.xml(network=True, peers=("10.0.0.7",))):
        assert "<Internal><GenerateKeyhash>true</GenerateKeyhash></Internal>" in xml
        assert f"<SPDPInterval>{config.SPDP_INTERVAL}</SPDPInterval>" in xml and config.SPDP_INTERVAL == "1s"
        assert "<InitialLocatorPruneDelay>inf</InitialLocatorPruneDelay>" in xml


def test_cmd_vel_is_read_best_effort_and_the_estop_reliably() -> None:
    """A best-effort reader matches best-effort and reliable writers; a recording still
    offers /cmd_vel reliable, as rclcpp's publishers do."""
    cmd_vel = topics.by_name("/cmd_vel")
    assert not cmd_vel.live.reliable and cmd_vel.profile.reliable
    assert topics.by_name("/estop").live.reliable and topics.by_name("/estop_reset").live.reliable


def test_no_python_312_skips_here_and_fails_under_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.ros2 import jazzy_env
    from tests.ros2.conftest import jazzy_python_or_skip

    monkeypatch.setattr(jazzy_env, "python312_candidates", lambda: [Path("/nonexistent/bin/python3.12")])
    with pytest.raises(pytest.skip.Exception, match=r"no Python 3\.12 .* /nonexistent/bin/python3\.12"):
        jazzy_python_or_skip(ci=False)
    with pytest.raises(pytest.fail.Exception, match=r"CI=true: no Python 3\.12"):
        jazzy_python_or_skip(ci=True)


def test_a_failed_build_fails(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A build step that fails is a failure, naming the step, even without CI."""
    from tests.ros2 import jazzy_env
    from tests.ros2.conftest import jazzy_python_or_skip

    monkeypatch.setattr(jazzy_env, "cache_root", lambda: tmp_path)
    monkeypatch.setattr(jazzy_env, "WHEELS", ("ros-jazzy-no-such-wheel-exists==0.0.0",))
    monkeypatch.setattr(jazzy_env, "BUILD_WHEELS", ())
    monkeypatch.setenv("PIP_NO_INDEX", "1")                      # no look-up: the install fails here
    with pytest.raises(pytest.fail.Exception, match="pip install of the ros-jazzy wheels failed"):
        jazzy_python_or_skip(ci=False)
