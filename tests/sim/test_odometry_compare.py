"""Seed 002's comparison, short (``benchmarks/odometry_compare.py`` runs the full
table): down the hospital corridor at 0.5 m/s with the left tyre on a wet floor (mu
0.08, as ``slip_turn``), the wheels' odometry is decimetres off and ICP on the scans,
seeded by it, stays within a few centimetres of the truth; the EKF's gyro holds the
heading. Without slip the simulated wheels are exact to millimetres and ICP's error is
the scans' (noise, and the distortion of a turn taken while moving). ICP read through
a lidar mount turned the wrong way is the control: its error is the travel's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from wcdrive.plant.lidar import LidarMount
from wcdrive.sim import runner, scenario
from wcdrive.sim.compare import ESTIMATES, compare

CORRIDOR = scenario.BUNDLED / "worlds" / "hospital_corridor.yaml"


def _run(tmp_path: Path, friction_left: float | None):
    """4 m down the corridor in closed loop at 0.5 m/s (the host steering by its
    wheels), the S3 on the seed's mount, the EKFs on."""
    path = tmp_path / "drive.toml"
    chair = "" if friction_left is None else f"[chair]\nfriction_left = {friction_left}\n"
    path.write_text(f'settle_s = 0.5\npath = [[4.0, 0.0]]\n{chair}[follow]\nspeed = 0.5\nlookahead = 1.0\n'
                    f'timeout_s = 20\n[world]\nmap = "{CORRIDOR}"\nstart = [1.0, 1.0, 0]\n'
                    '[lidar]\nmodel = "rplidar_s3"\n')
    return runner.run(scenario.load(str(path)), ekf=True)


@pytest.fixture(scope="module")
def wet(tmp_path_factory: pytest.TempPathFactory):
    return _run(tmp_path_factory.mktemp("wet"), 0.08)


def test_icp_beats_the_wheels_under_slip(wet) -> None:
    m = wet.metrics()
    assert m["collisions"] == 0
    errors = compare(wet, only=("wheel", "ekf", "icp", "fused"))
    wheel, ekf, icp, fused = errors["wheel"], errors["ekf"], errors["icp"], errors["fused"]
    print({k: dataclasses.asdict(v) for k, v in errors.items()})
    assert wheel.final_m > 0.08                                  # the slip shows in the wheels
    assert icp.final_m < 0.5 * wheel.final_m and icp.final_m < 0.05
    assert icp.rms_m < 0.5 * wheel.rms_m
    assert abs(icp.heading_deg) < 1.0 < abs(wheel.heading_deg)
    assert icp.fallbacks is not None and icp.fallbacks <= 0.05 * icp.scans
    assert abs(ekf.heading_deg) < 0.5                            # the gyro holds the heading
    assert fused.final_m < 0.5 * wheel.final_m and fused.final_m < 0.05 and abs(fused.heading_deg) < 0.5


def test_a_mount_turned_the_wrong_way_is_seen(wet) -> None:
    """The control: the same scans read as from a lidar turned 180 deg, so that each
    step's motion comes out backwards: ICP rejects such steps by its jump check and
    falls back on the wheels', or it runs backwards, and its error is no better than
    theirs."""
    turned = LidarMount(x=0.20, z=0.30, yaw_deg=180.0)
    icp = compare(wet, only=("icp",), mount=turned)["icp"]
    wheel = compare(wet, only=("wheel",))["wheel"]
    assert icp.final_m > 0.5 * wheel.final_m


def test_without_slip_the_wheels_are_exact_and_icp_within_centimetres(tmp_path: Path) -> None:
    dry = _run(tmp_path, None)
    errors = compare(dry, only=("wheel", "icp"))
    assert errors["wheel"].final_m < 0.005
    assert errors["icp"].final_m < 0.03 and errors["icp"].rms_m < 0.05


def test_the_estimates_are_seed_002s() -> None:
    assert list(ESTIMATES) == ["wheel", "ekf", "icp", "icp_ekf", "fused"]
