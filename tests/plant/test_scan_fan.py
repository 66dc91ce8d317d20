"""A turn's fan (``RayGrid.fan_bins``): each ray tests only the items its direction's
bin lists, nearest first, and stops at the first bound past its nearest hit; its
figures are those of the grid walk, sample for sample (the same test on the same item
gives the same distance), on random worlds and drives, from a chair spinning fast or
parked on a wall, for any count of bins. The noise a C turn draws itself is numpy's
``Generator.standard_normal``'s; a track whose log starts before its turn is
integrated from its own start."""

from __future__ import annotations

import math
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant.lidar import Lidar, LidarMount, MotionTrack
from wcdrive.plant.raycast import MAX_FAN_BINS, RayGrid, ScanJob, Turn, draws_in_c
from wcdrive.plant.world import World

from .test_lidar_scan import ROOM, SANDBOX, _log, _same_scan

pytestmark = pytest.mark.skipif(RayGrid.build(np.array([[0.0, 0, 1, 0]]), np.zeros((0, 3))) is None,
                                reason="no C compiler: the C scan is not built")


def _q2(grid: RayGrid, lidar: Lidar, track: MotionTrack, t0: float, bins: int) -> np.ndarray:
    """Each sample's quarter millimetres of the turn from ``t0``, with ``bins`` bins (0:
    the walk), no noise."""
    grid.fan_bins = bins
    try:
        job = ScanJob(grid, lidar._turn, t0, None, motion=(track.start, track.log), motion_t0=track.t0)
        job.run()
        return job.q2.copy()
    finally:
        grid.fan_bins = 512


def _world(rng: np.random.Generator, n_seg: int, n_circ: int) -> World:
    """Random walls (short and long) and posts around the origin, and a room's outline."""
    a = rng.uniform(-6, 6, (n_seg, 2))
    length = rng.choice([0.05, 0.3, 3.0], n_seg) * rng.uniform(0.5, 1.5, n_seg)
    angle = rng.uniform(0, 2 * math.pi, n_seg)
    b = a + np.column_stack((length * np.cos(angle), length * np.sin(angle)))
    outline = [[-8, -8, 8, -8], [8, -8, 8, 8], [8, 8, -8, 8], [-8, 8, -8, -8]]
    seg = np.concatenate((np.column_stack((a, b)), outline))
    circ = np.column_stack((rng.uniform(-6, 6, (n_circ, 2)), rng.uniform(0.02, 0.4, n_circ)))
    return World(seg, circ)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 300), st.integers(0, 20), st.floats(-6.0, 6.0),
       st.floats(-0.3, 0.3), st.floats(-10.0, 10.0), st.sampled_from([32, 64, 512, 4096]),
       st.tuples(st.floats(-0.5, 0.5), st.floats(-0.3, 0.3), st.floats(-180, 180), st.booleans()))
def test_the_fan_meets_what_the_walk_meets(seed: int, n_seg: int, n_circ: int, forward: float,
                                           lateral: float, yaw_rate: float, bins: int,
                                           mount: tuple[float, float, float, bool]) -> None:
    """Random worlds, speeds up to 6 m/s and 10 rad/s (beyond the chair's: a turn's
    origins spread wide) changing step to step, mounts off the axle, turned and upside
    down: every sample's figure the walk's."""
    rng = np.random.default_rng(seed)
    world = _world(rng, n_seg, n_circ)
    grid = world.ray_grid
    assert grid is not None
    steps = int(rng.integers(1, 150))
    wobble = rng.uniform(0.5, 1.5, (3, steps))
    t0 = float(rng.uniform(0, 100))
    track = MotionTrack((float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)), float(rng.uniform(-4, 4))), t0,
                        _log(t0, steps, forward * wobble[0], lateral * wobble[1], yaw_rate * wobble[2]))
    lidar = Lidar(mount=LidarMount(x=mount[0], y=mount[1], yaw_deg=mount[2], inverted=mount[3]))
    walk = _q2(grid, lidar, track, t0, 0)
    assert np.array_equal(_q2(grid, lidar, track, t0, bins), walk)


@pytest.mark.parametrize("where", ["sandbox", "room"])
@pytest.mark.parametrize("speed, yaw_rate", [(0.0, 0.0), (0.4, 0.5), (1.5, 0.0), (0.0, 3.0), (-1.0, -2.0),
                                             (5.0, 1.0), (2.0, 8.0)])
def test_the_fan_on_a_ros_map_and_a_furnished_room(where: str, speed: float, yaw_rate: float) -> None:
    """Ten turns in a row on each, parked, driving a circle, fast straight, spinning,
    and faster than the chair can (each bin's bounds then the least of what follows)."""
    world, offset = (SANDBOX, (0.5, 0.3)) if where == "sandbox" else (ROOM, (0.0, 0.0))
    grid = world.ray_grid
    assert grid is not None
    lidar = Lidar(mount=LidarMount(x=0.30, z=0.45))
    start = (0.0, 0.0, 0.3)
    for turn in range(10):
        t0 = 0.1 * turn
        track = MotionTrack(start, t0, _log(t0, 100, speed, 0.0, yaw_rate), offset)
        walk = _q2(grid, lidar, track, t0, 0)
        assert (walk > 0).mean() > (0.5 if turn == 0 else 0.0)     # fast, it leaves the map
        assert np.array_equal(_q2(grid, lidar, track, t0, 512), walk)
        _, x, y, h = track.knots
        start = (x[-1] - offset[0], y[-1] - offset[1], h[-1])


@pytest.mark.parametrize("bins", [32, 512])
def test_a_lidar_on_a_wall_or_inside_a_post(bins: int) -> None:
    """The lidar's origin on a segment, and inside a circle (every item within the
    radius of the turn's origins is in every bin, from 0)."""
    world = World(np.array([[-1.0, 0.3, 1.0, 0.3], [-3, -3, 3, -3], [3, -3, 3, 3], [3, 3, -3, 3],
                            [-3, 3, -3, -3]]), np.array([[0.3, -1.0, 0.5]]))
    grid = world.ray_grid
    assert grid is not None
    lidar = Lidar(mount=LidarMount(x=0.0))
    for start in ((0.0, 0.3, 0.0), (0.3, -1.0, 1.0), (0.2, -0.7, 2.0)):
        for forward, yaw_rate in ((0.0, 0.0), (0.3, 1.0)):
            track = MotionTrack(start, 0.0, _log(0.0, 100, forward, 0.0, yaw_rate))
            walk = _q2(grid, lidar, track, 0.0, 0)
            assert np.array_equal(_q2(grid, lidar, track, 0.0, bins), walk)


def test_non_finite_poses_walk_as_before() -> None:
    """A pose that is not finite (a NaN in the log) gives no return, as the walk does."""
    grid = ROOM.ray_grid
    assert grid is not None
    log = _log(0.0, 100, 0.4, 0.0, 0.5)
    log[40:, 1] = np.nan
    track = MotionTrack((0.0, 0.0, 0.0), 0.0, log)
    lidar = Lidar()
    walk = _q2(grid, lidar, track, 0.0, 0)
    assert 0 < (walk > 0).sum() < len(walk)
    assert np.array_equal(_q2(grid, lidar, track, 0.0, 512), walk)


def test_fan_bins_out_of_range_are_refused() -> None:
    grid = ROOM.ray_grid
    assert grid is not None
    for bins in (-1, MAX_FAN_BINS + 1):
        with pytest.raises(ValueError, match="fan bins"):
            grid.fan_bins = bins
    assert grid.fan_bins == 512


def test_a_fan_too_large_to_build_walks() -> None:
    """1,500 rings around the lidar, each in every bin, at the most bins: 98 million
    entries, past the fan's limit; the turn walks the grid (the same figures)."""
    rings = np.column_stack((np.zeros((1500, 2)), np.linspace(0.5, 30.0, 1500)))
    world = World(np.zeros((0, 4)), rings)
    grid = world.ray_grid
    assert grid is not None
    lidar = Lidar()
    track = MotionTrack((0.0, 0.0, 0.0), 0.0, _log(0.0, 100, 0.4, 0.0, 0.5))
    walk = _q2(grid, lidar, track, 0.0, 0)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert np.array_equal(_q2(grid, lidar, track, 0.0, MAX_FAN_BINS), walk)
    assert (walk > 0).all()                             # the innermost ring all round
    # no fan of 1.2 GB was made
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak < 300_000   # kB


def test_directions_not_of_unit_length_walk() -> None:
    """A turn whose directions are 2 m long: the fan's bounds are for unit ones, so
    those rays walk the grid, which gives their figures in its own units. Long walls
    across each other: an item listed early can be met far off."""
    rng = np.random.default_rng(1)
    grid = World(rng.uniform(-5, 5, (200, 4)), np.zeros((0, 3))).ray_grid
    assert grid is not None
    m = Lidar().model
    angle = np.arange(m.samples) * 2 * math.pi / m.samples
    turn = Turn(m.sample_hz, 2.0 * np.column_stack((np.cos(angle), np.sin(angle))),
                np.arange(m.samples) * m.beams // m.samples, m.beams, 1, (0.3, 0.0), 0.0, 0.05, 40.0, 47.0,
                False)
    track = MotionTrack((0.0, 0.0, 0.0), 0.0, _log(0.0, 100, 0.4, 0.0, 0.5))
    q2 = []
    for bins in (0, 512):
        grid.fan_bins = bins
        job = ScanJob(grid, turn, 0.0, None, motion=(track.start, track.log))
        job.run()
        q2.append(job.q2)
    grid.fan_bins = 512
    assert (q2[0] > 0).mean() > 0.1 and np.array_equal(q2[0], q2[1])


@pytest.mark.skipif(not draws_in_c(), reason="this numpy ships no libnpyrandom.a")
def test_the_noise_a_job_draws_is_numpys() -> None:
    """A job drawing its noise in C gets ``standard_normal``'s draws of the same
    generator, and leaves it where numpy would."""
    grid = SANDBOX.ray_grid
    assert grid is not None
    lidar = Lidar(mount=LidarMount(x=0.3))
    track = MotionTrack((0.0, 0.0, 0.0), 0.0, _log(0.0, 100, 0.4, 0.0, 0.5), (0.5, 0.3))
    for seed in (0, 1, [5, 7]):
        drawn, given_ = np.random.default_rng(seed), np.random.default_rng(seed)
        job = ScanJob(grid, lidar._turn, 0.0, None, motion=(track.start, track.log), draw=drawn)
        job.run()
        want = ScanJob(grid, lidar._turn, 0.0, given_.standard_normal(lidar.model.samples),
                       motion=(track.start, track.log))
        want.run()
        assert np.array_equal(job.q2, want.q2) and np.array_equal(job.ranges, want.ranges)
        assert drawn.standard_normal() == given_.standard_normal()
    with pytest.raises(ValueError, match="not both"):
        ScanJob(grid, lidar._turn, 0.0, np.zeros(lidar.model.samples), motion=(track.start, track.log),
                draw=np.random.default_rng(0))


def test_a_track_that_starts_before_its_turn() -> None:
    """The turn from 0.1 s of a track from 0.0375 s (the log's start pose is not the
    turn's): the C turn integrates the log from the track's start, as numpy does."""
    lidar = Lidar(mount=LidarMount(x=0.3))
    t_track = 0.0375

    def track() -> MotionTrack:
        return MotionTrack((0.2, -0.1, 0.4), t_track, _log(t_track, 170, 1.2, 0.0, 1.5), (0.5, 0.3))

    made = track()
    got = lidar.scan(SANDBOX, made, 0.1, np.random.default_rng(3))
    _same_scan(got, lidar.scan_numpy(SANDBOX, track(), 0.1, np.random.default_rng(3)), allowed=2)
    # the track keeps the knots the scan integrated: numpy's
    assert np.allclose(np.stack(made.knots), np.stack(track().knots_numpy()), rtol=0, atol=1e-12)


def test_an_idle_scan_thread_sleeps() -> None:
    """After a job the pipe's thread watches for the next one at most 0.1 ms, then
    sleeps: a pipe left idle burns no core. In a process of its own, so that no thread
    another test left running counts."""
    script = """
import time
import numpy as np
from tests.plant.test_lidar_scan import ROOM, _log
from wcdrive.plant.lidar import Lidar, MotionTrack
from wcdrive.plant.raycast import ScanPipe
track = MotionTrack((0.0, 0.0, 0.0), 0.0, _log(0.0, 100, 0.4, 0.0, 0.5))
with ScanPipe() as pipe:
    for _ in range(3):
        Lidar().start_scan(ROOM, track, 0.0, None, pipe).result()
    cpu = time.process_time()
    time.sleep(0.3)
    print(time.process_time() - cpu)
"""
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, check=True)
    assert float(out.stdout) < 0.03
