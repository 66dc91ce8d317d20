"""Shared by the ROS 2 bridge's tests: run the independent DDS peer
(``dds_peer.py``) in another process, pick ROS domains no other run uses, and the
stock ROS 2 Jazzy rclpy (``jazzy_python``: the cached venv of ``jazzy_env.py``)."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from wcdrive.ros2.dds.config import MAX_DOMAIN_ID

PEER = Path(__file__).with_name("dds_peer.py")
#: Each process counts from its own start, wrapping within 100 to 232 (MAX_DOMAIN_ID): a
#: worker that ran many bridges once counted on to 233 and past, whose ports Cyclone DDS
#: cannot open (7400 + 250 x domain passes 65535).
_DOMAINS = (100 + (start + k) % (MAX_DOMAIN_ID - 99) for start in [(os.getpid() % 40) * 3]
            for k in itertools.count())


class IdleRobot:
    """A stand-in ``Robot`` that never moves, for building a ``ChairNode`` whose
    ``start()`` is not called (its topics and QoS only); also a scan source that has no
    scan."""

    link_ok = True
    command_limits = (1.0, 1.0)

    def wheel_angles(self, sample: object) -> tuple[float, float]:
        return 0.0, 0.0


def fresh_domain() -> int:
    """A ROS domain id for one bridge, unlikely to be another test run's (100 to 232)."""
    return next(_DOMAINS)


def run_peer(domain: int, mode: str, *args: str, timeout: float = 90.0) -> dict[str, Any]:
    """Runs the peer to the end; its JSON summary."""
    result = subprocess.run([sys.executable, str(PEER), "--domain", str(domain), "--mode", mode, *args],
                            capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, result.stderr[-3000:]
    return dict(json.loads(result.stdout.strip().splitlines()[-1]))


@pytest.fixture(scope="session")
def jazzy_python() -> Path:
    """The Python of a venv with the stock ROS 2 Jazzy rclpy on Fast DDS, built once
    per machine and cached (``jazzy_env``): ``jazzy_python_or_skip``."""
    return jazzy_python_or_skip()


def jazzy_python_or_skip(ci: bool | None = None) -> Path:
    """``jazzy_env.jazzy_python()``. Without a Python 3.12 the test is skipped, saying
    where it looked; with ``CI=true`` (``ci``) that is a failure, as a failed build
    always is."""
    from tests.ros2 import jazzy_env

    ci = os.environ.get("CI") == "true" if ci is None else ci
    start = time.monotonic()
    try:
        python, info = jazzy_env.jazzy_python()
    except LookupError as exc:
        if ci:
            pytest.fail(f"CI=true: {exc}")
        pytest.skip(str(exc))
    except jazzy_env.JazzyEnvError as exc:
        pytest.fail(f"building the stock ROS 2 Jazzy venv: {exc}")
    state = "cached" if info.get("cached") else f"built: {info.get('seconds')}"
    print(f"stock Jazzy rclpy venv {python} ({state}; {time.monotonic() - start:.1f} s here)")
    return python
