"""A scenario's lidar (``[lidar]``): parsed with clear errors, its mount overridable (a
head-down mount too); the runner takes a scan every turn, each beam at its own time,
and ``SimResult`` carries them (``--json``: a summary). The ranges are checked against
distances to the hospital corridor's walls worked out by hand, and against the
chair's true motion while it drives."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from wcdrive.plant.lidar import SEED_MOUNT, LaserScan
from wcdrive.plant.world import World
from wcdrive.sim import runner, scenario
from wcdrive.sim.report import table, to_json
from wcdrive.sim.scenario import BUNDLED, ScenarioError

CORRIDOR = BUNDLED / "worlds" / "hospital_corridor.yaml"
#: The S3's range noise (1 sigma, m), and the bound used here: 4 sigma.
SIGMA = 0.010
BOUND = 4 * SIGMA


def _write(tmp_path: Path, text: str, segments: str = "[[segment]]\nstop = true\nduration = 1.0\n",
           name: str = "w") -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text(f"settle_s = 0.0\n{text}\n{segments}")
    return str(path)


def _corridor(tmp_path: Path, lidar: str = "", start: str = "[1.0, 1.0, 0]", **kw: str) -> str:
    world = f'[world]\nmap = "{CORRIDOR}"\nstart = {start}\n'
    return _write(tmp_path, f'{world}[lidar]\nmodel = "rplidar_s3"\n{lidar}', **kw)


def _beam(scan: LaserScan, angle: float) -> int:
    """The beam published at ``angle`` (rad, laser frame)."""
    return round((angle - scan.angle_min) / scan.angle_increment)


# ---- parsing ----------------------------------------------------------------------------
def test_no_lidar_table_no_lidar(tmp_path: Path) -> None:
    sc = scenario.load(_write(tmp_path, f'[world]\nmap = "{CORRIDOR}"\nstart = [1, 1, 0]\n'))
    assert sc.lidar is None
    result = runner.run(sc)
    assert result.lidar is None
    assert not any(k.startswith("lidar") for k in result.metrics())


def test_the_lidar_table_fits_the_s3_on_the_seeds_mount(tmp_path: Path) -> None:
    sc = scenario.load(_corridor(tmp_path))
    assert sc.lidar is not None
    assert sc.lidar.model.name == "rplidar_s3" and sc.lidar.beams == 3240
    assert sc.lidar.mount == SEED_MOUNT == dataclasses.replace(SEED_MOUNT, x=0.20, y=0.0, z=0.30)
    assert sc.lidar.mount.tf_roll == 0.0


def test_the_mount_is_overridable_and_may_be_head_down(tmp_path: Path) -> None:
    sc = scenario.load(_corridor(tmp_path, "x = 0.35\ny = -0.05\nz = 0.6\nyaw_deg = 90\nroll_deg = 180\n"))
    mount = sc.lidar.mount
    assert (mount.x, mount.y, mount.z, mount.yaw_deg) == (0.35, -0.05, 0.6, 90.0)
    assert mount.inverted and not mount.driver_inverted and mount.tf_roll == math.pi
    told = scenario.load(_corridor(tmp_path, "roll_deg = 180\ndriver_inverted = true\n")).lidar.mount
    assert told.inverted and told.driver_inverted and told.tf_roll == 0.0


@pytest.mark.parametrize(("text", "message"), [
    ('[lidar]\nmodel = "ust10"\n', r"\[lidar\] model must be one of rplidar_s3"),
    ("[lidar]\nx = 0.2\n", r"\[lidar\] model must be one of"),
    ('[lidar]\nmodel = "rplidar_s3"\nroll_deg = 90\n', r"roll_deg is 0 .* or 180"),
    ('[lidar]\nmodel = "rplidar_s3"\nx = "front"\n', r"\[lidar\] x must be a finite number"),
    ('[lidar]\nmodel = "rplidar_s3"\nz = nan\n', r"\[lidar\] z must be a finite number"),
    ('[lidar]\nmodel = "rplidar_s3"\npitch_deg = 3\n', r"\[lidar\]: unknown keys: pitch_deg"),
    ('[lidar]\nmodel = "rplidar_s3"\ndriver_inverted = 1\n', "driver_inverted is true or false"),
    ('lidar = "rplidar_s3"\n', r"lidar is a table"),
])
def test_lidar_errors_name_the_field(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        scenario.load(_write(tmp_path, text))


def test_a_world_file_beside_the_scenario(tmp_path: Path) -> None:
    (tmp_path / "worlds").mkdir()
    (tmp_path / "worlds" / "box.toml").write_text('name = "box"\nwalls = [[0, 0, 4, 0, 4, 3, 0, 3, 0, 0]]\n'
                                                  "circles = [[3, 2, 0.1]]\n")
    sc = scenario.load(_write(tmp_path, '[world]\nfile = "worlds/box.toml"\nboxes = [[1, 2, 0.4, 0.4]]\n'
                                        "start = [1.5, 1, 0]\n"))
    assert sc.world is not None and sc.world.segments.shape == (8, 4) and sc.world.circles.shape == (1, 3)
    with pytest.raises(ScenarioError, match=r"\[world\] file .*unknown keys: doors"):
        (tmp_path / "worlds" / "bad.toml").write_text("doors = [[1, 2]]\n")
        scenario.load(_write(tmp_path, '[world]\nfile = "worlds/bad.toml"\n'))
    with pytest.raises(ScenarioError, match=r"\[world\] file"):
        scenario.load(_write(tmp_path, '[world]\nfile = "worlds/none.toml"\n'))


def test_the_bundled_furnished_room() -> None:
    sc = scenario.load("room_lidar")
    world = sc.world
    assert world is not None
    # 4 walls, 4 pieces of furniture (boxes: 4 sides each), 4 table legs and a pillar
    assert world.segments.shape == (4 + 4 * 4, 4) and world.circles.shape == (5, 3)
    # from the middle of the room (8 m x 6 m): the wardrobe's face 3.4 m west (it is
    # 0.6 m deep, y 2.4 to 3.6), the south wall 3 m; at y = 2 the west wall 4 m
    assert world.cast(np.array([4.0, 3.0]), np.array([math.pi, -math.pi / 2])) == pytest.approx([3.4, 3.0])
    assert world.cast(np.array([4.0, 2.0]), np.array([math.pi])) == pytest.approx([4.0])
    assert sc.lidar is not None and sc.lidar.mount.inverted and sc.lidar.mount.tf_roll == math.pi


# ---- the scans ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def still(tmp_path_factory: pytest.TempPathFactory):
    """The chair standing in the corridor at (1.0, 1.0) facing east for 1 s."""
    return runner.run(scenario.load(_corridor(tmp_path_factory.mktemp("still"))))


def test_a_scan_every_turn_each_with_every_beam(still) -> None:
    scans = still.lidar.scans
    assert len(scans) == 10                                           # 1.0 s at 10 Hz
    assert [s.stamp for s in scans] == pytest.approx([0.1 * k for k in range(10)])
    assert {len(s.ranges) for s in scans} == {3240}
    first = scans[0]
    assert first.frame_id == "laser"
    assert first.scan_time == pytest.approx(0.1) and first.time_increment == pytest.approx(0.1 / 3239)
    assert first.angle_min == pytest.approx(-math.pi) and first.angle_max == pytest.approx(math.pi)
    # each beam at its own time within its turn
    for scan in scans:
        t = scan.beam_time
        assert np.nanmin(t) >= scan.stamp and np.nanmax(t) < scan.stamp + 0.1
        assert np.nanmax(t) - np.nanmin(t) > 0.099


def test_ranges_are_the_distances_to_the_corridors_walls(still) -> None:
    """The lidar at (1.20, 1.00) in the map (the chair at 1.0, its mount 0.20 m ahead),
    facing east: the corridor's walls are at y = 0 and y = 2 and its west end at x = 0;
    the east end at x = 16. By hand: north 1.0 m, south 1.0 m, west 1.2 m, east 14.8 m,
    north-west at 45 deg sqrt(2) = 1.414 m (it meets y = 2 at x = 0.2)."""
    expected = {math.pi / 2: 1.0, -math.pi / 2: 1.0, math.pi - 1e-9: 1.2, 0.0: 14.8,
                3 * math.pi / 4: math.sqrt(2.0)}
    for scan in still.lidar.scans:
        for angle, distance in expected.items():
            assert scan.ranges[_beam(scan, angle)] == pytest.approx(distance, abs=BOUND), angle
    # and every beam within the noise of an independent cast at its published angle,
    # but where the driver's binning (up to a bin, 0.11 deg, off) meets an edge
    world = World.from_table({"map": str(CORRIDOR)})
    scan = still.lidar.scans[5]
    angles = scan.angle_min + np.arange(3240) * scan.angle_increment
    exact = world.cast_exact(np.array([1.2, 1.0]), angles)
    err = np.abs(scan.ranges - exact)
    assert np.mean(err < BOUND) > 0.98
    assert np.std((scan.ranges - exact)[err < BOUND]) == pytest.approx(SIGMA, rel=0.2)


def test_a_misplaced_lidar_is_seen(tmp_path: Path) -> None:
    """The same scan from a mount 0.35 m ahead: west 1.35 m, and the noise's bound
    tells it from the seed's."""
    sc = scenario.load(_corridor(tmp_path, "x = 0.35\n"))
    scan = runner.run(sc).lidar.scans[3]
    west = scan.ranges[_beam(scan, math.pi - 1e-9)]
    assert west == pytest.approx(1.35, abs=BOUND) and abs(west - 1.2) > BOUND


def test_a_head_down_lidar_sees_the_world_mirrored(tmp_path: Path) -> None:
    """Head down, the driver not told: the laser frame has a roll of pi, so the beam at
    +80 deg in it looks at -80 deg in the chair's frame (the corridor's south side). At
    (1.0, 0.8) the south wall is 0.8 m away, the north wall 1.2 m."""
    sc = scenario.load(_corridor(tmp_path, "roll_deg = 180\n", start="[1.0, 0.8, 0]"))
    scan = runner.run(sc).lidar.scans[2]
    a = math.radians(80)
    assert scan.ranges[_beam(scan, a)] == pytest.approx(0.8 / math.sin(a), abs=BOUND)
    assert scan.ranges[_beam(scan, -a)] == pytest.approx(1.2 / math.sin(a), abs=BOUND)


def test_a_driving_chairs_beams_are_cast_at_their_own_times(tmp_path: Path) -> None:
    """Driving east down the corridor at 0.5 m/s, the beam looking back west (device
    angle 0: the first sample of the turn) sees the west end from where the lidar was at
    the turn's start, and the one looking east (half a turn later) the east end from
    where it was 0.05 s on, 25 mm nearer: each within the noise of the true pose at its
    own time, and a scan whose beams were all cast at its stamp is 25 mm off."""
    path = tmp_path / "drive.toml"                     # closed loop: straight down the corridor
    path.write_text(f'settle_s = 0.0\npath = [[9.0, 0.0]]\n[follow]\nspeed = 0.5\nlookahead = 1.0\n'
                    f'timeout_s = 30\n[world]\nmap = "{CORRIDOR}"\nstart = [1.0, 1.0, 0]\n'
                    '[lidar]\nmodel = "rplidar_s3"\n')
    result = runner.run(scenario.load(str(path)))
    ticks, truth = result.board.tick_time, result.truth.pose
    west_err, east_err, east_frozen = [], [], []

    def at(t: float) -> tuple[float, float]:
        """The lidar's x and the chair's heading at ``t`` (the truth, between ticks)."""
        heading = float(np.interp(t, ticks, truth[:, 2]))
        return float(np.interp(t, ticks, truth[:, 0])) + 0.20 * math.cos(heading), heading

    for scan in result.lidar.scans[40:140]:                  # cruising at about 0.5 m/s
        for centre, end, err in ((_beam(scan, math.pi - 1e-9), 0.0, west_err),
                                 (_beam(scan, 0.0), 16.0, east_err)):
            # the 11 beams about the axis (within 0.6 deg), each range against the wall's
            # distance along its published angle
            for i in range(centre - 5, centre + 6):
                i = min(i, 3239)
                angle = scan.angle_min + i * scan.angle_increment
                x, heading = at(scan.beam_time[i])
                err.append(scan.ranges[i] * abs(math.cos(heading + angle)) - abs(end - x))
                if end:
                    x, heading = at(scan.stamp)
                    east_frozen.append(scan.ranges[i] * abs(math.cos(heading + angle)) - (end - x))
    speed = np.diff(np.interp([4.0, 14.0], ticks, truth[:, 0]))[0] / 10.0
    assert speed == pytest.approx(0.5, abs=0.02)
    # 1,100 samples each: the mean's noise is 10 / sqrt(1100) = 0.3 mm
    assert abs(np.mean(west_err)) < 0.002 and abs(np.mean(east_err)) < 0.002
    assert np.mean(east_frozen) == pytest.approx(-speed * 0.05, abs=0.002)


def test_the_lidar_leaves_the_runs_truth_as_it_was(tmp_path: Path) -> None:
    sc = scenario.load(_corridor(tmp_path, segments="[[segment]]\ncmdvel = [0.4, 0.3]\nduration = 1.55\n"))
    on, off = runner.run(sc), runner.run(dataclasses.replace(sc, lidar=None))
    for a, b in ((on.truth.step_time, off.truth.step_time), (on.truth.step_speed, off.truth.step_speed),
                 (on.truth.pose, off.truth.pose), (on.odometry.wheel, off.odometry.wheel)):
        assert np.array_equal(a, b)
    assert len(on.lidar.scans) == 15                          # 1.55 s: 15 whole turns


def test_json_summarises_the_scans(still) -> None:
    m = json.loads(to_json([still]))[0]
    assert m["lidar_model"] == "rplidar_s3" and m["lidar_scans"] == 10 and m["lidar_beams"] == 3240
    assert m["lidar_mount"] == [0.2, 0.0, 0.3, 0.0] and m["lidar_inverted"] is False
    assert m["lidar_first_stamp_s"] == 0.0 and m["lidar_last_stamp_s"] == pytest.approx(0.9)
    assert m["lidar_return_fraction"] == 1.0                  # a closed corridor: every beam returns
    assert m["lidar_nearest_m"] == pytest.approx(1.0, abs=6 * SIGMA)    # the least of 32,400 draws
    assert "  lidar: rplidar_s3 at (0.20, 0.00, 0.30) m, yaw 0 deg, 10 scans of 3240 beams" in table(still)


def test_the_corridor_lidar_scenario() -> None:
    result = runner.run(scenario.load("corridor_lidar"))
    m = result.metrics()
    assert m["collisions"] == 0 and m["goal_within_tolerance"]
    scans = result.lidar.scans
    assert len(scans) == math.floor(result.duration * 10 + 1e-9)
    assert {len(s.ranges) for s in scans} == {3240}
    assert np.all(np.diff([s.stamp for s in scans]) > 0)


def test_on_simavr_as_on_the_port(tmp_path: Path) -> None:
    """The compiled firmware drives the same plant: the same turns, the same noise
    draws, the ranges the same but where the two runs' poses (a tenth of a millimetre
    apart) put a beam on either side of an edge."""
    sc = scenario.load(_corridor(tmp_path, segments="[[segment]]\ncmdvel = [0.4, 0.2]\nduration = 1.0\n"))
    simavr, port = runner.run(sc, backend="simavr"), runner.run(sc)
    assert simavr.firmware_differences == 0
    assert len(simavr.lidar.scans) == len(port.lidar.scans) == 10
    gap = np.concatenate([np.abs(a.ranges - b.ranges) for a, b in zip(simavr.lidar.scans, port.lidar.scans,
                                                                      strict=True)])
    assert np.mean(gap < 0.01) > 0.98
