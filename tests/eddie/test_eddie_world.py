"""Eddie's PING))) and IR sensors read a scenario's ``[world]`` (a map, walls, boxes,
circles: ``wcdrive.plant.world``) through its ray cast, as the chair's lidar does;
``start`` places Eddie and its odometry is compared placed there."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pymunk
import pytest

from wcdrive.eddie import runner
from wcdrive.eddie.geometry import IR_MOUNTS, PING_MOUNTS, ir_distance
from wcdrive.eddie.plant import RangeSensors, add_wall
from wcdrive.plant.world import World
from wcdrive.sim.scenario import BUNDLED

#: A box room 4 m x 3 m and a post 0.1 m in radius at (3, 1.5).
ROOM = World.from_table({"walls": [[0, 0, 4, 0, 4, 3, 0, 3, 0, 0]], "circles": [[3.0, 1.5, 0.1]]})


def test_the_ping_sensors_see_a_worlds_post_and_walls() -> None:
    """Eddie at (2.0, 1.5) facing east: its PING))) sensors, 0.2 m ahead and 0.06 m
    either side, see the post's near side: 3.0 - sqrt(0.1^2 - 0.06^2) - 2.2 = 0.72 m.
    Facing north, the north wall: 3.0 - 1.5 - 0.2 = 1.3 m."""
    sensors = RangeSensors(pymunk.Space(), seed=3, world=ROOM)
    near = 3.0 - math.sqrt(0.1**2 - 0.06**2) - 2.2
    east = [sensors.ping((2.0, 1.5, 0.0)) for _ in range(50)]
    for pin in PING_MOUNTS:
        readings = np.array([r[pin] for r in east])
        # the cone's edge rays (15 deg) reach the post no nearer than the middle one here
        assert np.mean(readings) == pytest.approx(near, abs=0.004)
        assert np.std(readings) == pytest.approx(0.003 + 0.01 * near, rel=0.3)
    north = [sensors.ping((2.0, 1.5, math.pi / 2)) for _ in range(50)]
    assert np.mean([r[0] for r in north] + [r[1] for r in north]) == pytest.approx(1.3, abs=0.005)


def test_the_ir_sensors_see_the_world() -> None:
    """Facing east 0.5 m from the east wall (centre IR at x 3.7, the wall at 4.0: 0.30
    m); the side IRs, 30 deg off, see the wall farther: (4.0 - 3.69) / cos 30."""
    sensors = RangeSensors(pymunk.Space(), seed=1, world=World.from_table({"walls": [[4, -2, 4, 2]]}))
    reads = [sensors.adc((3.5, 0.0, 0.0)) for _ in range(40)]
    centre = np.median([ir_distance(r[2]) for r in reads])
    assert centre == pytest.approx(0.30, rel=0.05)
    side = (4.0 - (3.5 + IR_MOUNTS[1].ahead)) / math.cos(math.radians(30))
    left = np.median([ir_distance(r[1]) for r in reads])
    assert left == pytest.approx(side, rel=0.06)


def test_the_nearer_of_a_pymunk_wall_and_the_world() -> None:
    space = pymunk.Space()
    add_wall(space, (3.0, -1.0), (3.0, 1.0))                 # 0.79 m ahead (it is 0.01 m thick)
    sensors = RangeSensors(space, seed=2, world=World.from_table({"walls": [[2.5, -1, 2.5, 1]]}))
    assert np.mean([sensors.ping((2.0, 0.0, 0.0))[0] for _ in range(30)]) == pytest.approx(0.3, abs=0.004)
    alone = RangeSensors(space, seed=2)
    assert np.mean([alone.ping((2.0, 0.0, 0.0))[0] for _ in range(30)]) == pytest.approx(0.79, abs=0.006)


def test_the_bundled_pillar_scenario() -> None:
    """Eddie starts at (3.0, 2.2) in the furnished room facing the pillar (r 0.15 m at
    x 5.25) and drives 0.2 m/s for 5 s: the nearest PING))) reading is the pillar,
    within the noise of the true distance straight ahead, and the odometry, placed at
    the start, ends within millimetres of the truth."""
    result = runner.run(runner.load("pillar_ahead"))
    assert result.path_length_m == pytest.approx(0.98, abs=0.05)
    assert result.truth[0] == pytest.approx(3.0 + result.path_length_m, abs=0.02)
    assert result.nearest_ping is not None
    reading, true = result.nearest_ping
    # by hand: the sensors 0.2 m ahead of x = truth, 0.06 m off the pillar's centre line
    assert true == pytest.approx(5.25 - math.sqrt(0.15**2 - 0.06**2) - (result.truth[0] + 0.2), abs=0.01)
    assert abs(reading - true) < 0.04
    assert result.final_error_m < 0.02
    assert not result.notes


def test_a_world_file_relative_to_eddies_scenario(tmp_path: Path) -> None:
    room = BUNDLED / "worlds" / "furnished_room.toml"
    path = tmp_path / "eddie_room.toml"
    path.write_text(f'[world]\nfile = "{room}"\nstart = [6.0, 1.0, 90]\n[lidar]\nmodel = "rplidar_s3"\n'
                    "[[segment]]\ncmdvel = [0.2, 0.0]\nduration = 2.0\n")
    result = runner.run(runner.load(str(path)))
    assert result.truth[1] == pytest.approx(1.0 + 0.4, abs=0.05)     # north from the start
    assert result.final_error_m < 0.02
    assert result.notes == ["[lidar] not on Eddie: ignored"]
