"""Shared by the ROS 2 bridge's tests: run the independent DDS peer
(``dds_peer.py``) in another process, and pick ROS domains no other run uses."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

PEER = Path(__file__).with_name("dds_peer.py")
_DOMAINS = itertools.count(100 + (os.getpid() % 40) * 3)


class IdleRobot:
    """A stand-in ``Robot`` that never moves, for building a ``ChairNode`` whose
    ``start()`` is not called (its topics and QoS only); also a scan source that has no
    scan."""

    link_ok = True
    command_limits = (1.0, 1.0)

    def wheel_angles(self, sample: object) -> tuple[float, float]:
        return 0.0, 0.0


def fresh_domain() -> int:
    """A ROS domain id for one bridge, unlikely to be another test run's (100 to 222)."""
    return next(_DOMAINS)


def run_peer(domain: int, mode: str, *args: str, timeout: float = 90.0) -> dict[str, Any]:
    """Runs the peer to the end; its JSON summary."""
    result = subprocess.run([sys.executable, str(PEER), "--domain", str(domain), "--mode", mode, *args],
                            capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, result.stderr[-3000:]
    return dict(json.loads(result.stdout.strip().splitlines()[-1]))
