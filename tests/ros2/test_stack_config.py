"""The bridge in place of a Jazzy stack's diff_drive_controller: configured by the
controller's own YAML (copied as a stack's ``controllers.yaml`` holds it) and ROS's own
arguments, it is node ``/wheelchair_controller`` and its topics are where the stack
looks for them.

The end-to-end check runs ``wcdrive ros2`` itself (a subprocess, the command line a
user types) and an independent DDS participant (``stack_peer.py``, another process)
that drives it on ``/wheelchair_controller/cmd_vel`` and reads
``/wheelchair_controller/odom``: the limits hold the chair to the YAML's, the joints
carry the YAML's names, ``/tf`` and ``/tf_static`` are left to the stack's EKF and
robot_state_publisher, and ``/odom`` is that of a base_link 0.2 m ahead of the axle.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.ros2.conftest import IdleRobot, fresh_domain
from wcdrive.errors import WcdriveFileError
from wcdrive.tools import cli, ros2_node

PEER = Path(__file__).with_name("stack_peer.py")
REPO = Path(__file__).resolve().parents[2]

#: A stack's controllers.yaml, as ros2_control's controller manager and the controller
#: read it: the manager's section names the controller, the controller's its
#: parameters; a /** section for every node.
CONTROLLERS = """\
controller_manager:
  ros__parameters:
    update_rate: 50
    wheelchair_controller:
      type: diff_drive_controller/DiffDriveController

wheelchair_controller:
  ros__parameters:
    left_wheel_names: ["left_drive_joint"]
    right_wheel_names: ["right_drive_joint"]
    wheel_separation: 0.56
    wheel_radius: 0.1715
    odom_frame_id: odom
    base_frame_id: base_link
    enable_odom_tf: false          # robot_localization's EKF owns odom -> base_link
    publish_rate: 20.0
    cmd_vel_timeout: 0.5
    pose_covariance_diagonal: [0.001, 0.001, 1000000.0, 1000000.0, 1000000.0, 0.01]
    twist_covariance_diagonal: [0.001, 0.001, 1000000.0, 1000000.0, 1000000.0, 0.01]
    linear:
      x:
        max_velocity: 0.4
        min_velocity: -0.3
        max_acceleration: 0.3
    angular:
      z:
        max_velocity: 0.5
        max_acceleration: 1.0

/**:
  ros__parameters:
    use_sim_time: false
"""
#: The bridge's own parameters, as a launch file would add them.
OWN = ["-p", "publish_static_tf:=false", "-p", "base_frame_offset_x:=0.2"]


def _args(*argv: str) -> Any:
    return cli.parser().parse_args(["ros2", *argv])


def test_the_command_line_takes_ros_arguments_as_rcl_does(tmp_path: Path) -> None:
    """The URL first, the bridge's flags, then ``--ros-args``; flags after ``--``."""
    yaml = tmp_path / "controllers.yaml"
    yaml.write_text(CONTROLLERS)
    args = _args("sim://?speed=2", "--twist", "--ros-args", "--params-file", str(yaml),
                 "-r", "__node:=wheelchair_controller", *OWN, "--", "--seconds", "3")
    names, config, url = ros2_node.configure(args)
    assert (url, args.twist, args.seconds) == ("sim://?speed=2", True, 3.0)
    assert names.fully_qualified_name == "/wheelchair_controller"
    assert config.left_joints == ("left_drive_joint",) and config.enable_odom_tf is False
    assert config.linear.max_velocity == 0.4 and config.angular.max_acceleration == 1.0
    assert config.base_offset == 0.2 and config.publish_static_tf is False
    assert config.unused == ["wheel_separation", "wheel_radius"]
    # --url still works, and the default is sim:// with no ROS arguments at all
    assert ros2_node.configure(_args("--url", "sim://"))[2] == "sim://"
    plain_names, plain, _ = ros2_node.configure(_args())
    assert plain_names.fully_qualified_name == "/wcdrive" and plain.given == {}


@pytest.mark.parametrize(("argv", "says"), [
    (["--ros-args", "-p", "publish_rate:=20"], "write 20.0"),
    (["--ros-args", "-p", "linear.x.max_velocty:=1.0"], "did you mean 'linear.x.max_velocity'"),
    (["--ros-args", "-p", "linear.x.max_velocity:=-1.0"], "must be >= 0.0"),
    (["--ros-args", "-p", "cmd_vel_timeout:=0.0"], "needs a timeout above 0"),
    (["--ros-args", "-p", "left_wheel_names:=[a, b]", "-p", "right_wheel_names:=[c]"],
     "are different"),
    (["--ros-args", "-r", "__node:=/x"], "invalid name"),
    (["--ros-args", "--params-file", "/nonexistent.yaml"], "cannot read it"),
    (["--ros-args", "-p"], "trailing -p"),
    (["--ros-args", "--custom"], "unknown ROS arguments: ['--custom']"),
    (["a", "--url", "b"], "two URLs"),
    (["--ros-args", "-p", "lidar_mount:=[0.0, 0.0, 0.3, 0.5, 0.0, 0.0]"], "only 0 or pi"),
    (["--ros-args", "-p", "lidar_mount:=[0.0, 0.0, 0.3]"], "needs 6 values"),
    (["--ros-args", "-p", "lidar_driver:=urg_node"], "one of sllidar_ros2, rplidar_ros"),
    (["/dev/ttyACM0", "--ros-args", "-p", "lidar_inverted:=true"], "not a simulated robot"),
])
def test_what_the_bridge_cannot_take_is_named(argv: list[str], says: str) -> None:
    with pytest.raises(WcdriveFileError) as caught:
        ros2_node.configure(_args(*argv))
    assert says in str(caught.value), str(caught.value)


def test_an_unknown_parameter_lists_the_known_ones() -> None:
    with pytest.raises(WcdriveFileError) as caught:
        ros2_node.configure(_args("--ros-args", "-p", "wheels_per_side:=1"))
    first = str(caught.value).splitlines()[0]               # what `wcdrive ros2` prints
    for name in ("odom_frame_id", "base_frame_id", "enable_odom_tf", "left_wheel_names",
                 "right_wheel_names", "cmd_vel_timeout", "publish_rate", "pose_covariance_diagonal",
                 "twist_covariance_diagonal", "linear.x.max_velocity", "linear.x.min_velocity",
                 "linear.x.max_acceleration", "angular.z.max_velocity", "angular.z.max_acceleration",
                 "publish_static_tf", "base_frame_offset_x", "lidar_frame_id", "imu_frame_id",
                 "use_sim_time", "lidar_mount", "lidar_driver", "lidar_inverted",
                 "lidar_angle_compensate"):
        assert name in first, name
    assert "'wheels_per_side'" in first


def test_a_node_rename_moves_the_controllers_topics_and_only_them(tmp_path: Path) -> None:
    """``~/odom`` and ``~/cmd_vel`` follow the node, as diff_drive_controller's do; a
    namespace moves the relative topics (and prefixes the controller's frames, as its
    ``tf_frame_prefix_enable`` does); remaps apply after."""
    from wcdrive.ros2.dds.graph import RosNode
    from wcdrive.ros2.dds.node import ChairNode, Options

    def topics(*argv: str) -> tuple[dict[str, str], Any]:
        names, config, _ = ros2_node.configure(_args(*argv))
        ros = RosNode(names.name, names.namespace, domain=fresh_domain())
        try:
            node = ChairNode(IdleRobot(), ros, Options(names=names).with_parameters(config))  # type: ignore[arg-type]
            return node.topic_names, node.options
        finally:
            ros.close()

    plain, _ = topics()
    assert plain["/odom"] == "/odom" and plain["/cmd_vel"] == "/cmd_vel" and plain["/tf"] == "/tf"
    renamed, _ = topics("--ros-args", "-r", "__node:=wheelchair_controller")
    assert renamed["/odom"] == "/wheelchair_controller/odom"
    assert renamed["/cmd_vel"] == "/wheelchair_controller/cmd_vel"
    assert {renamed[t] for t in ("/tf", "/tf_static", "/joint_states", "/diagnostics", "/estop")} == {
        "/tf", "/tf_static", "/joint_states", "/diagnostics", "/estop"}
    spaced, options = topics("--ros-args", "-r", "__ns:=/chair")
    assert (spaced["/odom"], spaced["/joint_states"], spaced["/tf"]) == ("/chair/odom", "/chair/joint_states",
                                                                        "/tf")
    assert (options.odom_frame, options.base_frame) == ("chair/odom", "chair/base_link")
    remapped, _ = topics("--ros-args", "-r", "__node:=wheelchair_controller",
                         "-r", "~/cmd_vel:=/cmd_vel_nav", "-r", "wheelchair_controller:joint_states:=wheels")
    assert remapped["/cmd_vel"] == "/cmd_vel_nav" and remapped["/joint_states"] == "/wheels"
    assert remapped["/odom"] == "/wheelchair_controller/odom"
    named, _ = topics("--name", "chair1")                    # --name keeps the bridge's layout
    assert named["/odom"] == "/odom"


def test_base_frame_offset_worked_by_hand() -> None:
    """The axle at (1.0, 0.5) heading +y (θ = π/2), 0.3 m/s forward, turning 0.5 rad/s;
    base_link 0.2 m ahead of it. In the axle's odom frame base_link is at (1.0, 0.7)
    (0.2 m along +y); it started at (0.2, 0), so the odom frame, which puts base_link's
    start at the origin, is the axle's moved back 0.2 m in x: base_link is at (0.8, 0.7),
    heading π/2. Its velocity, in its own frame: 0.3 m/s forward, and sideways the
    turning rate times the lever, 0.5 · 0.2 = 0.1 m/s to the left; yaw rate 0.5. The
    yaw's variance (0.01) reaches x through the lever (x moves by -0.2 sin θ per radian):
    σxx = 0.001 + 0.2² · 0.01, σxθ = -0.2 · 0.01; y is unchanged (cos θ = 0)."""
    from types import SimpleNamespace

    import numpy as np

    from wcdrive.ros2.dds import messages

    pose_cov = np.diag([0.001, 0.002, 1e6, 1e6, 1e6, 0.01])
    twist_cov = np.diag([0.004, 0.0, 1e6, 1e6, 1e6, 0.02])
    estimate = SimpleNamespace(pose=SimpleNamespace(x=1.0, y=0.5, theta=math.pi / 2), linear=0.3, angular=0.5,
                               pose_covariance=pose_cov, twist_covariance=twist_cov)
    odom = messages.odometry(12.5, estimate, "odom", "base_link", offset=0.2)
    position, twist = odom["pose"]["pose"]["position"], odom["twist"]["twist"]
    assert (position["x"], position["y"]) == pytest.approx((0.8, 0.7), abs=1e-12)
    orientation = odom["pose"]["pose"]["orientation"]
    assert 2 * math.atan2(orientation["z"], orientation["w"]) == pytest.approx(math.pi / 2)
    assert (twist["linear"]["x"], twist["linear"]["y"], twist["angular"]["z"]) == pytest.approx(
        (0.3, 0.1, 0.5))
    pose = np.asarray(odom["pose"]["covariance"]).reshape(6, 6)
    assert pose[0, 0] == pytest.approx(0.001 + 0.04 * 0.01) and pose[0, 5] == pytest.approx(-0.2 * 0.01)
    assert pose[1, 1] == pytest.approx(0.002) and pose[1, 5] == pytest.approx(0.0, abs=1e-15)
    twist_c = np.asarray(odom["twist"]["covariance"]).reshape(6, 6)
    assert twist_c[1, 1] == pytest.approx(0.04 * 0.02) and twist_c[1, 5] == pytest.approx(0.2 * 0.02)
    still = messages.odometry(12.5, estimate, offset=0.0)       # no offset: the axle's own odometry
    assert still["pose"]["pose"]["position"]["x"] == 1.0 and still["twist"]["twist"]["linear"]["y"] == 0.0


class _Recorder:
    """A stand-in ``RosNode``: endpoints by name, and what was published."""

    name, namespace = "wheelchair_controller", "/"

    def __init__(self) -> None:
        self.published: dict[str, list[Any]] = {}

    def publisher(self, topic: str, msgtype: str, profile: Any) -> Any:
        from types import SimpleNamespace

        box = self.published.setdefault(topic, [])
        return SimpleNamespace(publish=box.append)

    def subscription(self, topic: str, msgtype: str, profile: Any) -> Any:
        from types import SimpleNamespace

        return SimpleNamespace(take=lambda N: [])

    def close(self) -> None:
        pass


class _ChairWithLidar(IdleRobot):
    """A robot with a lidar 0.3 m ahead of the axle, facing backward (a
    ``wcdrive.host.robot.LidarSurface`` whose lidar makes no scans)."""

    has_lidar = True

    def __init__(self) -> None:
        from types import SimpleNamespace

        self.lidar = SimpleNamespace(frame_id="laser", mount=SimpleNamespace(x=0.3, y=0.0, z=0.4, yaw=math.pi,
                                                                            tf_roll=0.0))

    def on_scan(self, callback: Any) -> None:
        pass

    def on_telemetry(self, callback: Any) -> None:
        pass

    def stop(self) -> None:
        pass


def test_the_lidar_parameters_mount_the_simulated_lidar(tmp_path: Path) -> None:
    """A URDF's laser joint (yaw pi, roll pi as ``3.14159``) and the driver's launch
    options, given as parameters, are the simulated lidar's: in place of the URL's own
    options of those names, in degrees there."""
    import wcdrive

    yaml = tmp_path / "controllers.yaml"
    yaml.write_text("wheelchair_controller:\n  ros__parameters:\n"
                    "    lidar_mount: [-0.30, 0.0, 0.25, 3.14159, 0.0, 3.14159]\n"
                    "    lidar_driver: rplidar_ros\n    lidar_inverted: true\n")
    url = ros2_node.configure(_args(
        "sim://?lidar=rplidar_s3&lidar_driver=sllidar_ros2&speed=2", "--ros-args", "--params-file",
        str(yaml), "-r", "__node:=wheelchair_controller", "-p", "lidar_angle_compensate:=false"))[2]
    assert url.startswith("sim://?lidar=rplidar_s3&speed=2&lidar_mount=-0.3,0.0,0.25,180.0,0.0,179.99")
    assert url.endswith("&lidar_driver=rplidar_ros&lidar_inverted=true&lidar_angle_compensate=false")
    from wcdrive.host.wheelchair import Wheelchair

    with wcdrive.connect(url) as chair:
        assert isinstance(chair, Wheelchair)
        lidar = chair.lidar
    assert lidar is not None
    mount, driver = lidar.mount, lidar.driver
    assert (mount.x, mount.y, mount.z) == (-0.3, 0.0, 0.25)
    assert mount.inverted and mount.driver_inverted and mount.yaw == pytest.approx(math.pi, abs=1e-5)
    assert (driver.name, driver.angle_compensate) == ("rplidar_ros", False)
    # a URL without a lidar: the parameters need one to mount, and say so
    with pytest.raises(Exception, match="needs lidar=rplidar_s3"):
        wcdrive.connect(ros2_node.configure(_args("sim://", "--ros-args", "-p", "lidar_inverted:=true"))[2])


@pytest.mark.parametrize("static", [True, False])
def test_static_transforms_follow_the_parameters(static: bool) -> None:
    """``publish_static_tf`` false: no ``/tf_static`` endpoint at all; otherwise the
    frames named by the parameters, the lidar measured from base_link (0.3 m ahead of
    the axle less base_frame_offset_x 0.2)."""
    from wcdrive.ros2.dds.node import ChairNode, Options

    names, config, _ = ros2_node.configure(_args(
        "--ros-args", "-r", "__node:=wheelchair_controller",
        "-p", f"publish_static_tf:={str(static).lower()}",
        "-p", "base_frame_offset_x:=0.2", "-p", "lidar_frame_id:=rplidar_link", "-p", "imu_frame_id:=imu",
        "-p", "base_frame_id:=chassis"))
    ros = _Recorder()
    node = ChairNode(_ChairWithLidar(), ros, Options(names=names).with_parameters(config))  # type: ignore[arg-type]
    try:
        node.start()
    finally:
        node.close()
    if not static:
        assert "/tf_static" not in ros.published and "/tf_static" not in node.published
        return
    (message,) = ros.published["/tf_static"]
    frames = {(t["header"]["frame_id"], t["child_frame_id"]): t["transform"]["translation"]
              for t in message["transforms"]}
    assert set(frames) == {("chassis", "imu"), ("chassis", "rplidar_link")}
    assert frames[("chassis", "rplidar_link")]["x"] == pytest.approx(0.1)


def test_publish_rate_thins_odometry_as_the_controller_does() -> None:
    """``publish_rate: 10.0`` over ticks 51 ms apart: every other tick (the controller's
    rule, ``previous + period < now``, then ``previous += period``); none given: every
    tick."""
    from wcdrive.ros2.dds.node import ChairNode, Options

    ticks = [100.0 + 0.051 * i for i in range(10)]
    node = ChairNode(IdleRobot(), _Recorder(), Options(publish_rate=10.0))  # type: ignore[arg-type]
    assert [node._odometry_due(t) for t in ticks] == [True, False, True, False, True, False, True, False,
                                                      True, False]
    every = ChairNode(IdleRobot(), _Recorder(), Options())  # type: ignore[arg-type]
    assert all(every._odometry_due(t) for t in ticks)


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """``wcdrive ros2`` configured as the stack's controller, driven by the peer."""
    yaml = tmp_path_factory.mktemp("stack") / "controllers.yaml"
    yaml.write_text(CONTROLLERS)
    domain = fresh_domain()
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = str(REPO)
    bridge = subprocess.Popen(
        [sys.executable, "-m", "wcdrive", "ros2", "sim://", "--domain", str(domain), "--seconds", "60",
         "--ros-args", "--params-file", str(yaml), "-r", "__node:=wheelchair_controller", *OWN],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert bridge.stdout is not None
        first = bridge.stdout.readline()
        assert "node /wheelchair_controller" in first, first + (bridge.stderr.read() if bridge.stderr else "")
        peer = subprocess.run([sys.executable, str(PEER), "--domain", str(domain)], capture_output=True,
                              text=True, timeout=120)
        assert peer.returncode == 0, peer.stderr[-3000:]
        result: dict[str, Any] = json.loads(peer.stdout.strip().splitlines()[-1])
    finally:
        bridge.send_signal(signal.SIGTERM)
        bridge.wait(timeout=30)
        out = bridge.stdout.read() if bridge.stdout else ""     # after readline: not communicate()
        for pipe in (bridge.stdout, bridge.stderr):
            if pipe is not None:
                pipe.close()
    result["bridge_stdout"] = first + out
    result["bridge_status"] = bridge.returncode
    return result


def test_the_stack_finds_the_bridge_where_it_finds_its_controller(stack: dict[str, Any]) -> None:
    assert stack["discovered"], stack
    endpoints = {tuple(e) for e in stack["endpoints"]}
    for expected in (("pub", "rt/wheelchair_controller/odom"), ("sub", "rt/wheelchair_controller/cmd_vel"),
                     ("pub", "rt/joint_states"), ("pub", "rt/diagnostics"), ("sub", "rt/estop")):
        assert expected in endpoints, (expected, endpoints)
    for absent in (("pub", "rt/odom"), ("sub", "rt/cmd_vel"), ("pub", "rt/tf"), ("pub", "rt/tf_static")):
        assert absent not in endpoints, absent           # the EKF and robot_state_publisher own those
    assert ["/", "wheelchair_controller"] in stack["nodes"]
    assert stack["joint_names"] == ["left_drive_joint", "right_drive_joint"]
    assert "/wheelchair_controller/cmd_vel is TwistStamped" in stack["bridge_stdout"]
    assert stack["bridge_status"] == 128 + signal.SIGTERM


def test_the_controllers_limits_hold_and_are_counted(stack: dict[str, Any]) -> None:
    odom = stack["odom"]
    assert odom and all((o[1], o[2]) == ("odom", "base_link") for o in odom)
    drive = [o for o in odom if stack["drive_start"] <= o[0] < stack["turn_start"]]
    turn = [o for o in odom if stack["turn_start"] + 0.5 <= o[0] < stack["coast_start"]]
    fastest = max(o[3] for o in drive)
    assert 0.3 < fastest <= 0.4 + 0.02, fastest           # 1.0 m/s asked, 0.4 m/s allowed
    reached = next(o[0] for o in drive if o[3] >= 0.3)
    assert reached - stack["drive_start"] >= 0.3 / 0.3 - 0.2, reached   # 0.3 m/s^2, not the board's ramp
    assert max(abs(o[5]) for o in turn) <= 0.5 + 0.03      # 1.0 rad/s asked, 0.5 allowed
    limits = stack["limits"][-1]
    assert float(limits["linear.x.max_velocity"]) == 0.4
    for counted in ("linear.x velocity limited", "linear.x acceleration limited",
                    "angular.z velocity limited"):
        assert int(limits[counted]) > 0, (counted, limits)
    # cmd_vel_timeout: the commands stop, the chair is stopped
    assert abs(odom[-1][3]) < 0.02 and abs(odom[-1][5]) < 0.05, odom[-1]


def test_odometry_is_the_base_frames_ahead_of_the_axle(stack: dict[str, Any]) -> None:
    """base_frame_offset_x 0.2: turning on the spot, base_link moves sideways at 0.2 ω."""
    turning = [o for o in stack["odom"] if abs(o[5]) > 0.2]
    assert turning
    for _, _, _, _vx, vy, wz, _ in turning:
        assert math.isclose(vy, 0.2 * wz, abs_tol=1e-9)
    assert all(o[6][0] == 0.001 for o in stack["odom"])      # pose_covariance_diagonal, as given


def test_the_bridge_names_its_topics_on_the_start_line(stack: dict[str, Any]) -> None:
    assert "odometry on /wheelchair_controller/odom" in stack["bridge_stdout"]
    assert "taken but not used: wheel_separation, wheel_radius" in stack["bridge_stdout"]


def test_the_peer_is_independent_of_wcdrive() -> None:
    for source in (PEER.read_text(), PEER.with_name("dds_peer.py").read_text()):
        assert "import wcdrive" not in source and "from wcdrive" not in source
