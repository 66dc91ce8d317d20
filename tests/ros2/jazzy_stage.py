"""One run of the bridge against the stock Jazzy rclpy (``jazzy_client.py`` in the venv
of ``jazzy_env.py``), staged in one process tree so that it can run inside a network
namespace of its own (``test_jazzy_rclpy.py`` starts it under ``unshare -rn`` when it
can: Jazzy's default discovery range, SUBNET, multicasts, and that stays in the
namespace). Run with wcdrive's Python:

1. bridge B (``sim://``) starts: the late joiners' target;
2. bridge A (``sim://`` among ``--world`` with a lidar) starts, and the ``main``
   client (Jazzy's default discovery range) checks it end to end and ends it with
   SIGTERM;
3. once ``--late`` s have passed since B started (longer than Cyclone's 30 s
   default pruning of unanswered peer addresses), four ``discover`` clients start at
   once, one per discovery setting (``PROBES``), and time how long each takes to see
   ``/wcdrive`` and its first ``/odom``;
4. B gets SIGTERM.

Meanwhile, while the late joiners wait, bridge C (``sim://`` among ``REPLICA_WALLS``
with a lidar) starts as a stack replaces its drive with it (``--params-file`` with a
``diff_drive_controller`` YAML and the stack's lidar mount, ``-r
__node:=wheelchair_controller``; ``REPLICA_YAML``) and the ``replica`` client reads its
scans and drives it as the stack would (``replica`` in the JSON).

Prints one JSON object: ``main``, ``discovery`` (by setting), the bridges' exit codes,
how long A took to exit after the SIGTERM, and ``late_s`` (when the probes started).

    python -m tests.ros2.jazzy_stage --python VENV/bin/python --domains 150,151 --world W.toml
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from tests.ros2.jazzy_env import client_env

CLIENT = Path(__file__).with_name("jazzy_client.py")
REPO = Path(__file__).resolve().parents[2]
#: The discovery settings of a ROS 2 Jazzy node the late joiners try (environment).
PROBES: dict[str, dict[str, str]] = {
    "SUBNET": {},                                               # Jazzy's default
    "LOCALHOST": {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
    "ROS_STATIC_PEERS": {"ROS_STATIC_PEERS": "127.0.0.1"},      # with the default range
    "ROS_LOCALHOST_ONLY": {"ROS_LOCALHOST_ONLY": "1"},           # Humble's switch, deprecated in Jazzy
}


#: The controller a stack names its drive after, and its YAML as the stack has it: the
#: EKF owns odom -> base_link, robot_state_publisher the static frames, and the
#: controller limits the speed. The lidar is the stack's: an RPLidar S3 under the
#: seat, head down and facing back (its URDF joint's origin), run by ``rplidar_ros``
#: with ``inverted:=true``.
CONTROLLER = "wheelchair_controller"
REPLICA_LIMIT_MPS = 0.2
#: The URDF's laser joint: x, y, z (m), roll, pitch, yaw (rad).
REPLICA_MOUNT = (-0.30, 0.0, 0.25, 3.14159, 0.0, 3.14159)
#: The replica's world (m, the chair at the origin facing +x): a wall 5 m ahead, and a
#: shorter one on the left only, so that a mirrored scan lands nowhere.
REPLICA_WALLS = [[5.0, -3.0, 5.0, 3.0], [1.0, 2.0, 3.0, 2.0]]
REPLICA_YAML = f"""{CONTROLLER}:
  ros__parameters:
    left_wheel_names: ["left_wheel_joint"]
    right_wheel_names: ["right_wheel_joint"]
    enable_odom_tf: false
    publish_static_tf: false
    lidar_mount: [{", ".join(map(str, REPLICA_MOUNT))}]
    lidar_driver: rplidar_ros
    lidar_inverted: true
    linear:
      x:
        max_velocity: {REPLICA_LIMIT_MPS}
"""


def start_bridge(domain: int, url: str, *ros_args: str) -> subprocess.Popen[str]:
    """``wcdrive ros2 --url URL`` in ``domain`` (with ``--ros-args`` ``ros_args`` when
    given), once it says its node is up."""
    extra = ["--ros-args", *ros_args] if ros_args else []
    bridge = subprocess.Popen([sys.executable, "-m", "wcdrive", "ros2", "--url", url, "--domain",
                               str(domain), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, cwd=REPO)
    assert bridge.stdout is not None
    line = bridge.stdout.readline()
    if "wcdrive ros2: node /" not in line:
        bridge.kill()
        raise RuntimeError(f"the bridge did not start: {line!r} {bridge.communicate()[1][-2000:]}")
    return bridge


def client(python: str, domain: int, *args: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen([python, str(CLIENT), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=client_env(domain, **(env or {})), cwd=REPO)


def result_of(process: subprocess.Popen[str], timeout: float) -> dict[str, Any]:
    out, err = process.communicate(timeout=timeout)
    lines = out.strip().splitlines()
    if process.returncode != 0 or not lines:
        return {"error": f"exit {process.returncode}", "stderr": err[-3000:]}
    return dict(json.loads(lines[-1]))


def stop(process: subprocess.Popen[str]) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", required=True, help="the venv's Python (jazzy_env)")
    parser.add_argument("--domains", required=True, help="A,B,C: the three bridges' ROS domains")
    parser.add_argument("--world", required=True, help="bridge A's world (a wall file)")
    parser.add_argument("--late", type=float, default=32.0, help="start the late joiners this long after B")
    args = parser.parse_args()
    domain_a, domain_b, domain_c = (int(d) for d in args.domains.split(","))
    out: dict[str, Any] = {}
    started: list[subprocess.Popen[str]] = []
    try:
        late_bridge = start_bridge(domain_b, "sim://")
        t0 = time.monotonic()
        started.append(late_bridge)
        bridge = start_bridge(domain_a, f"sim://?world={args.world}&lidar=rplidar_s3")
        started.append(bridge)
        main_client = client(args.python, domain_a, "--mode", "main", "--bridge-pid", str(bridge.pid))
        started.append(main_client)
        out["main"] = result_of(main_client, timeout=150)
        try:
            bridge.wait(timeout=15)
        except subprocess.TimeoutExpired:
            out["bridge_exit"] = "still running 15 s after SIGTERM"
        else:
            out["bridge_exit"] = bridge.returncode
            out["bridge_stderr"] = bridge.stderr.read()[-2000:] if bridge.stderr else ""
        params, world = (Path(args.world).with_name(name) for name in ("controllers.yaml", "replica.toml"))
        params.write_text(REPLICA_YAML)
        world.write_text(f"walls = {json.dumps(REPLICA_WALLS)}\n")
        replica_bridge = start_bridge(domain_c, f"sim://?world={world}&lidar=rplidar_s3", "--params-file",
                                      str(params), "-r", f"__node:={CONTROLLER}")
        started.append(replica_bridge)
        replica = client(args.python, domain_c, "--mode", "replica", "--controller", CONTROLLER)
        started.append(replica)
        out["replica"] = result_of(replica, timeout=60)
        stop(replica_bridge)
        time.sleep(max(0.0, t0 + args.late - time.monotonic()))
        out["late_s"] = round(time.monotonic() - t0, 1)
        probes = {name: client(args.python, domain_b, "--mode", "discover", "--name", f"late_{i}",
                               "--timeout", "20", env=env)
                  for i, (name, env) in enumerate(PROBES.items())}
        started += probes.values()
        out["discovery"] = {name: result_of(p, timeout=90) for name, p in probes.items()}
        late_bridge.terminate()
        out["late_bridge_exit"] = late_bridge.wait(timeout=15)
    finally:
        for process in reversed(started):
            stop(process)
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
