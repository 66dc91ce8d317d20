"""Who can see the bridge's participant: run by ``test_dds_safety`` (inside a network
namespace of its own when it can make one). For the default configuration and for
``network=True`` on ``--address``, starts a ``RosNode`` with a ``/odom`` publisher and
asks ``dds_peer.py --mode discover`` from 127.0.0.1 and from ``--address`` whether it
sees ``rt/odom``. Prints ``{"default": {addr: seen}, "network": {addr: seen}}``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from wcdrive.ros2.dds import qos
from wcdrive.ros2.dds.graph import RosNode

PEER = Path(__file__).with_name("dds_peer.py")


def seen(domain: int, address: str, timeout: float) -> bool:
    out = subprocess.run([sys.executable, str(PEER), "--domain", str(domain), "--mode", "discover",
                          "--address", address, "--discovery-timeout", str(timeout)],
                         capture_output=True, text=True, timeout=timeout + 30)
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return bool(json.loads(out.stdout)["seen"])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--address", required=True)
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--timeout", type=float, default=4.0)
    args = ap.parse_args()
    result: dict[str, dict[str, bool]] = {}
    for mode, network in (("default", False), ("network", True)):
        node = RosNode("wcdrive", domain=args.domain, network=network,
                       peers=(args.address,) if network else (), interface=args.address if network else None)
        try:
            node.publisher("/odom", "nav_msgs/msg/Odometry", qos.DEFAULT)
            addresses = ("127.0.0.1", args.address) if not network else (args.address,)
            result[mode] = {a: seen(args.domain, a, args.timeout) for a in addresses}
        finally:
            node.close()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
