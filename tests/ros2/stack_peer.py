"""A stack's view of the bridge, for ``test_stack_config.py``: an independent DDS
participant (``dds_peer.py``'s types and configuration; it never imports wcdrive) that
plays the nodes of a Jazzy stack around a bridge named after its diff_drive_controller.

It waits for the bridge's ``<prefix>/cmd_vel`` reader, reads ``<prefix>/odom``,
``/joint_states``, ``/diagnostics`` and the graph topic, then sends TwistStamped
buffers at 20 Hz on ``<prefix>/cmd_vel`` (built byte by byte, as a Jazzy publisher
sends them): ``--linear`` m/s straight for ``--drive`` s, then ``--angular`` rad/s on
the spot for ``--turn`` s, then nothing for ``--coast`` s (the command times out).
Prints a JSON summary: the bridge's endpoints, each ``/odom`` (arrival time, stamp,
frames, speeds), the joint names, the last ``wcdrive: limits`` status and the nodes.

    python stack_peer.py --domain 117 --prefix /wheelchair_controller
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from cyclonedds.pub import DataWriter
from dds_peer import Peer, qos, twist_stamped


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--prefix", default="/wheelchair_controller")
    ap.add_argument("--linear", type=float, default=1.0)
    ap.add_argument("--angular", type=float, default=1.0)
    ap.add_argument("--drive", type=float, default=2.5)
    ap.add_argument("--turn", type=float, default=2.0)
    ap.add_argument("--coast", type=float, default=2.0)
    ap.add_argument("--discovery-timeout", type=float, default=20.0)
    args = ap.parse_args()
    from cyclonedds._clayer import ddspy_write

    peer = Peer(args.domain, "127.0.0.1")
    reliable = qos(True)
    odom, cmd = "rt" + args.prefix + "/odom", "rt" + args.prefix + "/cmd_vel"
    peer.read(odom, "nav_msgs/msg/Odometry", reliable)
    peer.read("rt/joint_states", "sensor_msgs/msg/JointState", reliable)
    peer.read("rt/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", reliable)
    peer.read("ros_discovery_info", "rmw_dds_common/msg/ParticipantEntitiesInfo",
              qos(True, transient=True, depth=1))
    writer = DataWriter(peer.dp, peer.topic(cmd, "geometry_msgs/msg/TwistStamped"), qos=reliable)
    result: dict[str, Any] = {"discovered": peer.wait_for(cmd, "sub", args.discovery_timeout)
                              and peer.wait_for(odom, "pub", args.discovery_timeout)}
    deadline = time.monotonic() + args.discovery_timeout
    while writer.get_publication_matched_status().current_count < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    arrivals: list[list[Any]] = []
    start = time.monotonic()
    phases = [("drive", args.drive, args.linear, 0.0), ("turn", args.turn, 0.0, args.angular),
              ("coast", args.coast, None, None)]
    for name, seconds, linear, angular in phases:
        end = time.monotonic() + seconds
        result[f"{name}_start"] = time.monotonic() - start
        while time.monotonic() < end:
            if linear is not None and angular is not None:
                wall = time.time()
                ddspy_write(writer._ref, twist_stamped(int(wall), int((wall % 1) * 1e9), "base_link",
                                                       (linear, 0.0, 0.0), (0.0, 0.0, angular)))
            for sample in peer.readers[odom].take(N=64):
                if sample.sample_info.valid_data:
                    t = sample.twist.twist
                    arrivals.append([time.monotonic() - start, sample.header.frame_id, sample.child_frame_id,
                                     t.linear.x, t.linear.y, t.angular.z, list(sample.pose.covariance)[:8]])
            time.sleep(0.05)
    peer.poll()
    received = peer.received
    result["odom"] = arrivals
    result["endpoints"] = sorted({(e["kind"], e["topic"]) for e in peer.endpoints()})
    result["joint_names"] = sorted({n for m in received["rt/joint_states"] for n in m.name})
    result["limits"] = [{kv.key: kv.value for kv in s.values} for m in received["rt/diagnostics"]
                        for s in m.status if s.name == "wcdrive: limits"][-1:]
    result["nodes"] = sorted({(n.node_namespace, n.node_name) for info in received["ros_discovery_info"]
                              for n in info.node_entities_info_seq})
    print(json.dumps(result))


if __name__ == "__main__":
    main()
