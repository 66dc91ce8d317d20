"""``wcdrive ros2``'s reading of the URL: which robots are simulated (no warning under
``--network``) and which run faster than real time (``/clock`` by default)."""

from __future__ import annotations

from wcdrive.tools.ros2_node import faster_than_real_time, simulated


def test_simulated_urls() -> None:
    for url in ("sim://", "simavr://", "simavr:///tmp/fw.elf?realtime=0", "eddie+sim://", "wcsim://"):
        assert simulated(url), url
    for url in ("/dev/ttyACM0", "eddie:///dev/ttyUSB0", "can://socketcan/can0", "socket://host:1",
                "simulated", "sim:/"):
        assert not simulated(url), url


def test_faster_than_real_time() -> None:
    assert faster_than_real_time("sim://?speed=2")
    assert faster_than_real_time("eddie+sim://?speed=4&seed=1")
    assert faster_than_real_time("simavr://?realtime=0")
    for url in ("sim://", "sim://?speed=1", "sim://?speed=0.5", "simavr://?realtime=1",
                "/dev/ttyACM0", "socket://host:1?speed=9"):
        assert not faster_than_real_time(url), url


def test_the_flags_choose_the_topics() -> None:
    """``--no-tf`` drops ``/tf``; ``/imu`` needs a gyro tap, ``/scan`` a scan source,
    ``/clock`` sim time; ``--twist`` makes ``/cmd_vel`` a plain Twist reader."""
    from tests.ros2.conftest import IdleRobot as Idle
    from tests.ros2.conftest import fresh_domain
    from wcdrive.ros2.dds.graph import RosNode
    from wcdrive.ros2.dds.node import ChairNode, ImuTap, Options

    ros = RosNode("wcdrive", domain=fresh_domain())
    try:
        plain = ChairNode(Idle(), ros, Options(publish_tf=False))       # type: ignore[arg-type]
        assert sorted(plain.published) == ["/diagnostics", "/joint_states", "/odom", "/tf_static"]
        full = ChairNode(Idle(), ros, Options(twist=True, sim_time=True, scan=Idle()),  # type: ignore[arg-type]
                         imu=ImuTap())
        assert sorted(full.published) == ["/clock", "/diagnostics", "/imu", "/joint_states", "/odom",
                                          "/scan", "/tf", "/tf_static"]
        assert full._cmd_type == "geometry_msgs/msg/Twist" and plain._cmd_type.endswith("TwistStamped")
    finally:
        ros.close()
