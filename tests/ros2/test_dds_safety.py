"""Who may drive the chair through the bridge, and what is never driven.

- By default the bridge is reachable from this host only: a participant bound to a
  non-loopback address does not see it, one on 127.0.0.1 does, and ``network=True``
  makes it visible on that address (in a network namespace the test makes, with a
  veth interface, when ``unshare -rn`` works, as root or in a user namespace; else on
  this host's own address).
- Stale, non-finite and out-of-range ``/cmd_vel`` samples are dropped and counted;
  ``/estop`` latches and then every ``/cmd_vel`` is dropped.
- A DDS stack that is missing or cannot start, and multicast that does not work, fail
  with an error naming them; ``--network`` on a real device says who can drive.
"""

from __future__ import annotations

import json
import math
import shutil
import socket
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import wcdrive
from tests.ros2.conftest import PEER, fresh_domain
from wcdrive.errors import WcdriveConnectionError
from wcdrive.ros2.dds import config, multicast
from wcdrive.ros2.dds.cmdvel import CmdVelGate
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.dds.node import ChairNode, Options

PROBE = Path(__file__).with_name("reach_probe.py")
REPO = Path(__file__).resolve().parents[2]
NETNS = ("ip link set lo up && ip link add wa type veth peer name wb && "
         "ip addr add 198.51.100.1/24 dev wa && ip link set wa up && ip link set wb up && ")


def _host_address() -> str | None:
    """A non-loopback IPv4 address of this host, if it has one."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.255", 9))
            address = str(s.getsockname()[0])
    except OSError:
        return None
    return None if address.startswith("127.") else address


def _reach(domain: int) -> dict[str, Any]:
    """``reach_probe.py`` in a network namespace of its own, else on this host."""
    if shutil.which("unshare") and shutil.which("ip") and subprocess.run(
            ["unshare", "-rn", "sh", "-c", NETNS + "true"], capture_output=True).returncode == 0:
        command = ["unshare", "-rn", "sh", "-c",
                   NETNS + f"exec {sys.executable} {PROBE} --address 198.51.100.1 --domain {domain}"]
    else:
        address = _host_address()
        if address is None:
            pytest.skip("no network namespace (unshare -rn, ip) and no non-loopback address here")
        command = [sys.executable, str(PROBE), "--address", address, "--domain", str(domain)]
    out = subprocess.run(command, capture_output=True, text=True, timeout=90, cwd=REPO)
    assert out.returncode == 0, out.stderr[-3000:]
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def test_by_default_only_this_host_sees_the_bridge_and_network_opts_in() -> None:
    result = _reach(fresh_domain())
    default, network = result["default"], result["network"]
    other = next(a for a in network)
    assert default == {"127.0.0.1": True, other: False}, result
    assert network == {other: True}, result


def test_the_default_configuration_is_loopback_only() -> None:
    local = config.xml()
    assert '<NetworkInterface address="127.0.0.1"/>' in local
    assert "<AllowMulticast>false</AllowMulticast>" in local
    assert local.count("<Peer ") == 1 and '<Peer address="127.0.0.1"/>' in local
    lan = config.xml(network=True, peers=("10.0.0.7",))
    assert "127.0.0.1" not in lan and "AllowMulticast" not in lan and '<Peer address="10.0.0.7"/>' in lan
    with pytest.raises(wcdrive.WcdriveError, match="need --network"):
        config.xml(peers=("10.0.0.7",))


def test_ros_domain_id_is_read_and_checked() -> None:
    assert config.domain_id({}) == 0
    assert config.domain_id({"ROS_DOMAIN_ID": "42"}) == 42
    for bad in ("233", "-1", "x"):
        with pytest.raises(wcdrive.WcdriveError, match="ROS_DOMAIN_ID"):
            config.domain_id({"ROS_DOMAIN_ID": bad})


# ---- the gate ------------------------------------------------------------------------
def _twist(x: float = 0.0, z: float = 0.0, **other: float) -> dict[str, Any]:
    return {"linear": {"x": x, "y": other.get("y", 0.0), "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": z}}


def test_the_gate_drops_and_counts_stale_non_finite_and_out_of_range() -> None:
    gate = CmdVelGate(max_linear=1.0, max_angular=2.0, max_age=0.5)
    now = 1000.0
    assert gate.check(_twist(0.5, 0.1), now, {"sec": 1000, "nanosec": 0}) == (0.5, 0.1)
    assert gate.check(_twist(0.5), now, {"sec": 0, "nanosec": 0}) == (0.5, 0.0)     # zero: now
    assert gate.check(_twist(0.5), now) == (0.5, 0.0)                                # Twist
    assert gate.check(_twist(0.5), now, {"sec": 999, "nanosec": 400_000_000}) is None  # 0.6 s old
    assert gate.check(_twist(0.5), now, {"sec": 1001, "nanosec": 0}) is None        # the future
    assert gate.check(_twist(math.nan), now) is None
    assert gate.check(_twist(0.1, y=math.inf), now) is None
    assert gate.check(_twist(1.01), now) is None
    assert gate.check(_twist(0.0, -2.01), now) is None
    assert gate.check(_twist(-1.0, 2.0), now) == (-1.0, 2.0)                        # the limits
    assert dict(gate.counts) == {"accepted": 4, "stale": 2, "non_finite": 2, "out_of_range": 2}
    assert gate.dropped == 6


@pytest.fixture(scope="module")
def bad() -> Iterator[dict[str, Any]]:
    """The peer's ``bad`` run against the bridge on ``sim://`` here; the e-stop as the
    chair reported it while the peer held it, and at the end."""
    domain = fresh_domain()
    chair = wcdrive.connect("sim://")
    assert isinstance(chair, wcdrive.Wheelchair)
    node = ChairNode(chair, RosNode("wcdrive", domain=domain), Options())
    try:
        node.start()
        peer = subprocess.Popen([sys.executable, str(PEER), "--domain", str(domain), "--mode", "bad"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert peer.stderr is not None
        latched_during = False
        for line in peer.stderr:
            if "estop held" in line:
                latched_during = chair.estop_latched and node.estop_held
                break
        out, err = peer.communicate(timeout=90)
        assert peer.returncode == 0, err
        counts = dict(node.gate.counts)
        latched = chair.estop_latched
    finally:
        node.close()
        chair.close()
    yield {"peer": json.loads(out.strip().splitlines()[-1]), "counts": counts,
           "latched_during": latched_during, "latched": latched}


def test_stale_non_finite_and_out_of_range_cmd_vel_never_drive(bad: dict[str, Any]) -> None:
    """Each bad kind for 0.6 s at 20 Hz leaves /odom's speed at zero; good ones then drive."""
    peer, counts = bad["peer"], bad["counts"]
    for kind in ("stale", "nan", "inf", "too_fast"):
        assert 0.0 <= peer[kind] < 0.01, (kind, peer)
    assert peer["good"] > 0.1, peer
    assert counts["stale"] >= 6 and counts["non_finite"] >= 12 and counts["out_of_range"] >= 6, counts


def test_estop_latches_and_drops_cmd_vel_until_estop_reset(bad: dict[str, Any]) -> None:
    assert bad["latched_during"], bad["peer"]
    assert bad["peer"]["after_estop"] < 0.01, bad["peer"]
    assert bad["counts"]["estop"] >= 10, bad["counts"]
    assert bad["peer"]["after_reset"] > 0.1, bad["peer"]          # /estop_reset, then it drives
    assert not bad["latched"]


# ---- errors that name the cause ----------------------------------------------------------
def _wcdrive(*args: str, prelude: str = "", timeout: float = 60) -> subprocess.CompletedProcess[str]:
    code = prelude + "import sys\nfrom wcdrive.tools.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)


def test_a_missing_dds_stack_says_what_to_install() -> None:
    block = textwrap.dedent("""
        import importlib.abc, sys
        class Block(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name == "cyclonedds" or name.startswith("cyclonedds."):
                    raise ImportError("No module named 'cyclonedds'")
        sys.meta_path.insert(0, Block())
    """)
    out = _wcdrive("ros2", "--seconds", "0.1", prelude=block)
    assert out.returncode == 2, out
    assert "pip install cyclonedds" in out.stderr and "Cyclone DDS" in out.stderr, out.stderr


def test_a_dds_stack_that_cannot_start_is_named() -> None:
    with pytest.raises(WcdriveConnectionError, match="Cyclone DDS could not join ROS 2 domain"):
        RosNode("wcdrive", domain=fresh_domain(), network=True, peers=("203.0.113.9",),
                interface="203.0.113.9")          # an address no interface here has


def test_blocked_multicast_is_named() -> None:
    """In a namespace with only loopback (no multicast route), ``--network`` without
    ``--peer`` stops at the multicast check."""
    if subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode != 0:
        with pytest.raises(WcdriveConnectionError, match="multicast"):
            multicast.check("203.0.113.9")        # not an address of this host
        return
    code = ("from wcdrive.tools.cli import main; import sys; "
            "sys.exit(main(['ros2', '--network', '--seconds', '1']))")
    shell = f"ip link set lo up && exec {sys.executable} -c \"{code}\""
    out = subprocess.run(["unshare", "-rn", "sh", "-c", shell],
                         capture_output=True, text=True, timeout=60, cwd=REPO)
    assert out.returncode == 3, out
    assert "multicast does not work here" in out.stderr and "--peer" in out.stderr, out.stderr


def test_network_on_a_real_device_says_anyone_can_drive_it() -> None:
    out = _wcdrive("ros2", "--url", "/dev/wcdrive-no-such-chair", "--network", "--peer", "127.0.0.1",
                   "--domain", str(fresh_domain()))
    assert "ANY node in ROS 2 domain" in out.stderr and "SROS2" in out.stderr, out.stderr
    assert out.returncode == 3 and "no such device" in out.stderr, out
    quiet = _wcdrive("ros2", "--url", "sim://", "--network", "--peer", "127.0.0.1", "--seconds", "0.2",
                     "--domain", str(fresh_domain()))
    assert quiet.returncode == 0, quiet.stderr
    assert "ANY node" not in quiet.stderr


def test_cyclonedds_uri_cannot_widen_the_bridge(monkeypatch: pytest.MonkeyPatch) -> None:
    """The bridge's configuration is its own: a ``CYCLONEDDS_URI`` naming an address no
    interface has (which Cyclone refuses to start with) changes nothing."""
    monkeypatch.setenv("CYCLONEDDS_URI", '<CycloneDDS><Domain><General><Interfaces><NetworkInterface '
                       'address="203.0.113.9"/></Interfaces></General></Domain></CycloneDDS>')
    out = _wcdrive("ros2", "--seconds", "0.2", "--domain", str(fresh_domain()))
    assert out.returncode == 0, out.stderr
