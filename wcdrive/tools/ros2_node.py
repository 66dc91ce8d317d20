"""``wcdrive ros2``: a chair (any URL ``wcdrive.connect`` takes) as a ROS 2 node on
DDS, for Nav2, slam_toolbox, robot_localization on this machine (docs/ros2.md).

    wcdrive ros2 --url sim://                     this host only (the default)
    wcdrive ros2 --url /dev/ttyACM0 --no-tf       an EKF publishes odom -> base_link
    wcdrive ros2 --url sim:// --network           the LAN: anyone in the domain can drive
    wcdrive ros2 sim:// --ros-args --params-file controllers.yaml -r __node:=wheelchair_controller
                                                  in a ROS 2 stack, as its diff_drive_controller

The URL may come first, without ``--url``. ``--ros-args … [--]`` takes ROS 2's own
arguments as rcl reads them (``wcdrive.ros2.rosargs``): ``-r``/``--remap`` rules
(topics, ``__node:=``, ``__ns:=``), ``-p``/``--param name:=value`` and
``--params-file FILE``; the parameters are diff_drive_controller's names and the
bridge's own (``wcdrive.ros2.controller``). They are checked before DDS is joined: a
bad rule, an unknown parameter or a value of the wrong type ends the command at once
(status 2), naming what to fix.

It joins ``ROS_DOMAIN_ID`` (``--domain``) before connecting, so that a DDS stack
that cannot start fails before the chair is touched; then connects, starts a
``wcdrive.ros2.dds.node.ChairNode`` and serves until Ctrl-C, SIGTERM or ``--seconds``.
On the way out it stops the chair, leaves the graph and closes the link; if it is
killed instead, the board's watchdog stops the chair 500 ms after the last command.

``--network`` on a real device (not ``sim://``, ``simavr://``, ``eddie+sim://``) prints
that any node in the domain can then drive the chair, and where to read about
SROS2 / DDS Security.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any
from urllib.parse import parse_qs, urlsplit

#: URL schemes of simulated robots (no person in a chair).
SIMULATED = ("sim", "simavr", "wcsim", "wcavr", "eddie+sim", "wceddie")
NETWORK_WARNING = (
    "wcdrive ros2: WARNING: --network on a real chair: plain DDS has no authentication, so "
    "ANY node in ROS 2 domain {domain} on this network can publish /cmd_vel and drive this "
    "chair with a person in it. Lock the domain down with SROS2 (DDS Security: "
    "https://docs.ros.org/en/jazzy/Tutorials/Advanced/Security/Introducing-ros2-security.html) "
    "or leave out --network (this host only).")


def simulated(url: str) -> bool:
    """Whether ``url`` is a simulated robot."""
    return url.partition("://")[0] in SIMULATED and "://" in url


def faster_than_real_time(url: str) -> bool:
    """Whether a simulated ``url`` runs faster than the wall clock (``speed`` above 1,
    or simavr's ``realtime=0``): then ``/clock`` carries its time."""
    if not simulated(url):
        return False
    query = parse_qs(urlsplit(url.replace("+", "-", 1)).query)
    try:
        speed = float(query.get("speed", ["1"])[0])
    except ValueError:
        speed = 1.0
    return speed > 1.0 or query.get("realtime", ["1"])[0] == "0"


class RosArgsParser(argparse.ArgumentParser):
    """The ``ros2`` subcommand's parser: ROS 2's arguments (``--ros-args … --``, and
    deprecated bare remap rules) are taken out as rcl takes them
    (``wcdrive.ros2.rosargs.parse_arguments``) into ``ros_args`` (or, when rcl would
    refuse them, ``ros_args_error``, which ``run`` raises); the rest is parsed as usual."""

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        """``argparse.ArgumentParser.parse_known_args``, ROS arguments taken out first."""
        from wcdrive.ros2.rosargs import RosArguments, RosArgumentsError, parse_arguments

        argv = list(sys.argv[1:] if args is None else args)
        ros, error = RosArguments(), None
        try:
            ros, argv = parse_arguments(argv)
        except RosArgumentsError as exc:         # raised by run(), as every error of the command
            error = exc
            argv = argv[:argv.index("--ros-args")] if "--ros-args" in argv else argv
        parsed, extras = super().parse_known_args(argv, namespace)
        parsed.ros_args, parsed.ros_args_error = ros, error
        return parsed, extras


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Adds ``ros2`` to the ``wcdrive`` command's subcommands."""
    p = sub.add_parser("ros2", help="the chair as a ROS 2 node on DDS (no ROS install needed)",
                       description="The chair (any URL connect() takes) as a ROS 2 node on DDS, "
                                   "without a ROS install: docs/ros2.md. ROS 2's own arguments "
                                   "follow --ros-args: -r/--remap FROM:=TO, -p/--param NAME:=VALUE, "
                                   "--params-file FILE, ended by --.",
                       epilog="e.g. wcdrive ros2 sim:// --ros-args --params-file controllers.yaml "
                              "-r __node:=wheelchair_controller")
    p.__class__ = RosArgsParser          # ROS arguments out first, as rcl takes them
    p.add_argument("url_arg", nargs="?", metavar="URL", help="the robot (or --url)")
    p.add_argument("--url", default=None, help="the robot: any URL connect() takes (default sim://)")
    p.add_argument("--name", default="wcdrive", help="the node's name (default wcdrive)")
    p.add_argument("--domain", type=int, help="the ROS 2 domain (default $ROS_DOMAIN_ID, else 0)")
    p.add_argument("--twist", action="store_true",
                   help="/cmd_vel is geometry_msgs/Twist (default: TwistStamped, Jazzy's)")
    p.add_argument("--no-tf", action="store_true", help="do not publish odom -> base_link (an EKF does)")
    p.add_argument("--cmd-timeout", type=float, default=0.5,
                   help="stop when no good /cmd_vel came for this long (s, default 0.5)")
    p.add_argument("--max-age", type=float, default=None,
                   help="drop a TwistStamped stamped further than this from now (s, default 0.5, "
                        "or the cmd_vel_timeout parameter)")
    p.add_argument("--sim-time", choices=("auto", "on", "off"), default="auto",
                   help="publish /clock and stamp with the board's clock (auto: when the "
                        "backend runs faster than real time)")
    p.add_argument("--network", action="store_true",
                   help="join the ROS graph on the network (default: this host only)")
    p.add_argument("--peer", action="append", default=[],
                   help="--network: a host to discover by unicast (repeatable)")
    p.add_argument("--interface", help="--network: the interface name or address to use")
    p.add_argument("--seconds", type=float, help="stop after this long (default: until Ctrl-C)")
    p.set_defaults(func=run)


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)


def configure(args: argparse.Namespace) -> tuple[Any, Any, str]:
    """(the node's ``NodeNames``, its ``StackConfig``, the URL) from the command line:
    the remap rules and parameters of ``--ros-args`` applied to the node ``--name``, as
    rclpy applies them; ``WcdriveFileError`` for what cannot be taken."""
    from wcdrive.errors import WcdriveFileError
    from wcdrive.ros2.controller import configure as configure_parameters
    from wcdrive.ros2.names import NodeNames

    if getattr(args, "ros_args_error", None) is not None:
        raise args.ros_args_error
    if args.url_arg is not None and args.url is not None and args.url_arg != args.url:
        raise WcdriveFileError(f"two URLs: {args.url_arg} and --url {args.url}: give one")
    url = args.url_arg or args.url or "sim://"
    ros_args = args.ros_args
    for warning in ros_args.warnings:
        print(f"wcdrive ros2: warning: {warning}", file=sys.stderr, flush=True)
    names = NodeNames.init(args.name, "/", ros_args.remaps)
    values = ros_args.parameters.for_node(names.fully_qualified_name)
    where = (f" (from {', '.join(ros_args.param_files)})" if ros_args.param_files else "")
    config = configure_parameters(values, names.namespace, names.fully_qualified_name + where)
    return names, config, with_lidar_parameters(url, config)


def with_lidar_parameters(url: str, config: Any) -> str:
    """``url`` with the simulated lidar the parameters ask for (``lidar_mount`` and the
    rest: ``wcdrive.ros2.controller.lidar_url_options``) in place of its own options of
    those names: the parameters are the stack's word on the lidar. On a URL that is not
    a simulated robot they are a ``WcdriveFileError``: a real lidar has its own driver."""
    from wcdrive.errors import WcdriveFileError
    from wcdrive.ros2.controller import lidar_url_options

    options = lidar_url_options(config)
    if not options:
        return url
    if not simulated(url):
        raise WcdriveFileError(f"{', '.join(options)}: these parameters set the simulated lidar, and {url} "
                               "is not a simulated robot (a real lidar has its own driver node)")
    base, _, query = url.partition("?")
    kept = [pair for pair in query.split("&") if pair and pair.partition("=")[0] not in options]
    return base + "?" + "&".join(kept + [f"{name}={value}" for name, value in options.items()])


def run(args: argparse.Namespace) -> int:
    """``wcdrive ros2`` (module docstring)."""
    import wcdrive
    from wcdrive.ros2.dds.config import domain_id
    from wcdrive.ros2.dds.graph import RosNode

    names, config, url = configure(args)           # before anything: a bad argument stops here
    domain = domain_id() if args.domain is None else args.domain
    if args.network and not simulated(url):
        print(NETWORK_WARNING.format(domain=domain), file=sys.stderr, flush=True)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
    ros = RosNode(names.name, names.namespace, domain=domain, network=args.network, peers=tuple(args.peer),
                  interface=args.interface)            # first: a DDS stack that fails, fails here
    from wcdrive.ros2.dds.node import ChairNode, ImuTap, Options

    try:
        tap = ImuTap() if url.startswith(("sim://", "simavr://", "wcsim://", "wcavr://")) else None
        chair = wcdrive.connect(url, ros=tap) if tap is not None else wcdrive.connect(url)
        with chair:
            sim_time = {"on": True, "off": False}.get(args.sim_time, faster_than_real_time(url))
            options = Options(twist=args.twist, publish_tf=not args.no_tf, cmd_timeout=args.cmd_timeout,
                              sim_time=sim_time, names=names).with_parameters(config)
            if args.max_age is not None:
                options.max_age = args.max_age
            if args.sim_time != "auto":          # the flag over use_sim_time
                options.sim_time = sim_time
            node = ChairNode(chair, ros, options, imu=tap).start()
            try:
                where = "the network" if args.network else "this host only"
                topics = node.topic_names
                print(f"wcdrive ros2: node {names.fully_qualified_name} on ROS 2 domain {domain} ({where}), "
                      f"driving {url}; {topics['/cmd_vel']} is {'Twist' if args.twist else 'TwistStamped'}, "
                      f"odometry on {topics['/odom']}" + (", /clock on" if options.sim_time else "")
                      + "; Ctrl-C to stop", flush=True)
                if config.given:
                    print(f"wcdrive ros2: parameters: {_describe(config)}", flush=True)
                end = time.monotonic() + args.seconds if args.seconds else None
                while end is None or time.monotonic() < end:
                    time.sleep(0.1)
            finally:
                node.close()            # stops the chair, leaves the graph; then the link closes
                print(f"wcdrive ros2: /cmd_vel {dict(sorted(node.gate.counts.items()))}", flush=True)
                if node.limiter.active:         # control periods each limit was active in
                    counts = dict(sorted(node.limiter.counts.items()))
                    print(f"wcdrive ros2: limits active {counts or 'never'}", flush=True)
    finally:
        ros.close()
    return 0


def _describe(config: Any) -> str:
    """The parameters given, and those taken but not used, for the start-up line."""
    used = [name for name in config.given if name not in config.unused]
    text = f"{len(used)} applied ({', '.join(used)})"
    if config.unused:
        text += (f"; taken but not used: {', '.join(config.unused)} (the chair's own geometry and "
                 "odometry rule those)")
    return text
