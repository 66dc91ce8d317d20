"""The lidar's turn in C (``Lidar.scan``) against the numpy reference
(``Lidar.scan_numpy``): the same published ranges, intensities and beam times from the
same noise draws, for a chair driving through a ROS map's outline and a furnished
room, on random motion logs and mounts; the poses a motion log integrates to, in C and
in numpy, and against the plant's own; the driver's last bin, which only a sample
whose bins reach it fills; turns made on a ``ScanPipe``'s thread are the same as
those made at once, in the order of their noise draws, waited for in any order."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant import raycast
from wcdrive.plant.lidar import LaserScan, Lidar, LidarMount, MotionTrack
from wcdrive.plant.raycast import ScanJob, ScanPipe
from wcdrive.plant.rosmap import load_map
from wcdrive.plant.world import World
from wcdrive.testing.stepped import SteppedChair

MAPS = Path(__file__).resolve().parents[1] / "data" / "rosmaps"
ROOM = World.from_table({
    "walls": [[-3, -2.5, 5, -2.5, 5, 3.5, -3, 3.5, -3, -2.5], [1.5, 3.5, 1.5, 1.8], [1.5, 0.9, 1.5, -0.4]],
    "boxes": [[3.6, 2.4, 2.0, 1.4], [-2.4, 2.6, 1.0, 0.6, 10], [-0.2, 3.1, 1.2, 0.5]],
    "circles": [[2.6, -1.6, 0.03], [3.4, -1.6, 0.03], [2.6, -1.0, 0.03], [3.4, -1.0, 0.03],
                [-1.5, -1.5, 0.15]],
})
SANDBOX = World.from_grid(load_map(MAPS / "tb3_sandbox.yaml"))


@pytest.fixture(scope="module")
def sandbox() -> World:
    return SANDBOX


def _log(t0: float, steps: int, forward: float | np.ndarray, lateral: float | np.ndarray,
         yaw_rate: float | np.ndarray, dt: float = 0.001) -> np.ndarray:
    """A motion log's rows: time, forward, lateral, yaw rate, and two volts."""
    log = np.zeros((steps, 6))
    log[:, 0] = t0 + dt * np.arange(1, steps + 1)
    log[:, 1], log[:, 2], log[:, 3] = forward, lateral, yaw_rate
    return log


def _same_scan(got: LaserScan, want: LaserScan, allowed: int = 0) -> None:
    """The same message; ``allowed`` beams may differ where a range lies within rounding of
    a half quarter millimetre (the C poses and directions round differently)."""
    assert got.ranges.dtype == want.ranges.dtype == np.float32 and got.intensities.dtype == np.float32
    assert (got.stamp, got.angle_min, got.angle_increment, got.time_increment) == \
        (want.stamp, want.angle_min, want.angle_increment, want.time_increment)
    differ = np.flatnonzero(got.ranges != want.ranges)
    assert len(differ) <= allowed, (differ[:5], got.ranges[differ[:5]], want.ranges[differ[:5]])
    assert np.abs(got.ranges[differ].astype(float) - want.ranges[differ]).max(initial=0.0) <= 0.00026
    same = np.ones(len(got.ranges), bool)
    same[differ] = False
    assert np.array_equal(got.intensities[same], want.intensities[same])
    assert np.array_equal(got.beam_time[same], want.beam_time[same], equal_nan=True)


@pytest.mark.parametrize("where", ["sandbox", "room"])
def test_a_turn_in_c_is_the_reference_s(where: str, sandbox: World) -> None:
    """Driving a circle at 0.4 m/s, 0.5 rad/s, the lidar 0.3 m ahead: ten turns in a
    row, each with its noise from one generator, in C and in numpy."""
    world, offset = (sandbox, (0.5, 0.3)) if where == "sandbox" else (ROOM, (0.0, 0.0))
    lidar = Lidar(mount=LidarMount(x=0.30, z=0.45))
    fast, slow = np.random.default_rng(5), np.random.default_rng(5)
    start = (0.0, 0.0, 0.0)
    for turn in range(10):
        t0 = 0.1 * turn
        track = MotionTrack(start, t0, _log(t0, 100, 0.4, 0.0, 0.5), offset)
        got = lidar.scan(world, track, t0, fast)
        want = lidar.scan_numpy(world, track, t0, slow)
        _same_scan(got, want)
        assert np.isfinite(got.ranges).mean() > 0.9
        _, x, y, h = track.knots
        start = (x[-1] - offset[0], y[-1] - offset[1], h[-1])
    assert fast.standard_normal() == slow.standard_normal()        # as many draws each way


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-1.5, 1.5), st.floats(-0.2, 0.2), st.floats(-3.0, 3.0),
       st.integers(1, 150), st.tuples(st.floats(-0.5, 0.5), st.floats(-0.3, 0.3), st.floats(-180, 180)),
       st.booleans(), st.booleans(), st.booleans())
def test_random_drives_and_mounts(seed: int, forward: float, lateral: float, yaw_rate: float, steps: int,
                                  mount: tuple[float, float, float], inverted: bool, told: bool,
                                  noisy: bool) -> None:
    """Random speeds (changing from step to step), a log that ends before the turn does
    (the pose held after its last step), mounts off the axle, turned, head down, the
    driver told or not; the room and the sandbox's outline."""
    rng = np.random.default_rng(seed)
    wobble = rng.uniform(0.5, 1.5, (3, steps))
    t0 = float(rng.uniform(0, 100))
    log = _log(t0, steps, forward * wobble[0], lateral * wobble[1], yaw_rate * wobble[2])
    start = (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), float(rng.uniform(-math.pi, math.pi)))
    track = MotionTrack(start, t0, log)
    lidar = Lidar(mount=LidarMount(x=mount[0], y=mount[1], yaw_deg=mount[2], inverted=inverted,
                                   driver_inverted=told))
    for world in (ROOM, SANDBOX):
        got = lidar.scan(world, track, t0, np.random.default_rng(seed) if noisy else None)
        want = lidar.scan_numpy(world, track, t0, np.random.default_rng(seed) if noisy else None)
        _same_scan(got, want, allowed=2)


def test_any_pose_at_is_asked_for_each_sample_s_pose(sandbox: World) -> None:
    """A ``pose_at`` that is not a motion track: its poses at the samples' times."""
    def pose_at(t: np.ndarray):
        return -0.5 + 0.8 * t, 0.4 + 0.1 * np.sin(t * 20), 0.3 + 1.5 * t

    lidar = Lidar(mount=LidarMount(x=0.2, y=-0.05))
    _same_scan(lidar.scan(sandbox, pose_at, 0.0), lidar.scan_numpy(sandbox, pose_at, 0.0))


def test_the_track_s_knots_in_c_and_in_numpy_and_the_plant_s_pose() -> None:
    """The knots integrated in C are numpy's to rounding; and a turn's log integrated
    from the pose at its start lands where the plant is at its end (to 0.1 mm)."""
    chair = SteppedChair()
    chair.set_velocity(0.4, 0.5)
    chair.run(0.5)
    plant = chair.plant
    plant.start_motion_log()
    for _ in range(5):
        start, t0 = plant.pose, plant.time
        chair.run(0.1)
        track = MotionTrack(start, t0, plant.take_motion_log(), offset=(2.0, -1.0))
        for a, b in zip(track.knots, track.knots_numpy(), strict=True):
            assert np.allclose(a, b, rtol=0, atol=1e-12)
        x, y, h = track(np.array([plant.time]))
        assert math.hypot(x[0] - 2.0 - plant.pose[0], y[0] + 1.0 - plant.pose[1]) < 1e-4
        assert abs(h[0] - plant.pose[2]) < 1e-4


@pytest.mark.parametrize("told", [False, True])
def test_the_last_bin_is_filled_only_by_a_sample_that_reaches_it(told: bool) -> None:
    """A wall only on the left (y = 3): the samples of the turn's first half return,
    the second half's do not. The driver's last bin (published first unless told
    ``inverted``) is filled only by a sample whose bins reach it: none here."""
    world = World.from_table({"walls": [[-100, 3, 100, 3]]})
    lidar = Lidar(mount=LidarMount(driver_inverted=told))

    def still(t: np.ndarray):
        return np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)

    for scan in (lidar.scan(world, still, 0.0), lidar.scan_numpy(world, still, 0.0)):
        ranges = scan.ranges if told else scan.ranges[::-1]         # in the driver's bin order
        assert math.isinf(ranges[-1]) and math.isnan((scan.beam_time if told else scan.beam_time[::-1])[-1])
        assert np.isfinite(ranges[100:1500]).all() and np.isinf(ranges[1700:]).all()


def test_without_the_c_helper_the_scan_is_the_reference_s(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(raycast, "_lib", False)
    world = World.from_table(ROOM_TABLE)
    assert world.ray_grid is None
    track = MotionTrack((0.0, 0.0, 0.2), 0.0, _log(0.0, 100, 0.3, 0.0, -0.4))
    got = Lidar().scan(world, track, 0.0, np.random.default_rng(1))
    _same_scan(got, Lidar().scan_numpy(world, track, 0.0, np.random.default_rng(1)))


ROOM_TABLE = {"walls": [[5, -2, 5, 3, -5, 3, -5, -2, 5, -2]], "circles": [[1, 1, 0.2]]}


def test_bad_knots_and_noise_are_errors(sandbox: World) -> None:
    grid = sandbox.ray_grid
    assert grid is not None
    lidar = Lidar()
    one = np.zeros(1)
    with pytest.raises(ValueError, match="knots"):
        grid.scan(lidar._turn, 0.0, (one, one, one, np.zeros(2)), None)
    with pytest.raises(ValueError, match="knots"):
        grid.scan(lidar._turn, 0.0, (np.zeros(0),) * 4, None)
    with pytest.raises(ValueError, match="3200 draws"):
        grid.scan(lidar._turn, 0.0, (one, one, one, one), np.zeros(10))


def _turns(n: int) -> list[tuple[float, MotionTrack]]:
    """n turns of a chair on a circle through the sandbox, 0.1 s each."""
    out = []
    start = (0.0, 0.0, 0.0)
    for k in range(n):
        t0 = 0.1 * k
        track = MotionTrack(start, t0, _log(t0, 100, 0.4, 0.0, 0.5), (0.5, 0.3))
        _, x, y, h = track.knots_numpy()
        start = (x[-1] - 0.5, y[-1] - 0.3, h[-1])
        out.append((t0, track))
    return out


def test_turns_made_on_the_pipe_s_thread_are_those_made_at_once() -> None:
    """Eight turns queued at once, their noise from one generator: each the same as
    made at once in the same order; waited for out of order (the waiting thread makes
    the ones still queued, and the rest of one begun); a result asked for twice is
    the same; then four more on the same pipe, made by it before it closes; the
    generator drew as much either way."""
    lidar = Lidar(mount=LidarMount(x=0.3))
    turns = _turns(12)
    now, later = np.random.default_rng(11), np.random.default_rng(11)
    want = [lidar.scan(SANDBOX, track, t0, now) for t0, track in turns]
    with ScanPipe() as pipe:
        pending = [lidar.start_scan(SANDBOX, track, t0, later, pipe) for t0, track in turns[:8]]
        got: list[LaserScan | None] = [None] * 8
        for k in (4, 0, 7, 2, 6, 1, 5, 3):
            got[k] = pending[k].result()
        assert pending[3].result() is got[3]
        pending = [lidar.start_scan(SANDBOX, track, t0, later, pipe) for t0, track in turns[8:]]
    got += [p.result() for p in pending]            # made by the pipe before it closed
    for g, w in zip(got, want, strict=True):
        assert g is not None
        _same_scan(g, w)
        assert g.stamp == w.stamp
    assert now.standard_normal() == later.standard_normal()


def test_closing_the_pipe_finishes_what_is_queued() -> None:
    lidar = Lidar()
    grid = SANDBOX.ray_grid
    assert grid is not None
    turns = _turns(4)
    jobs = [ScanJob(grid, lidar._turn, t0, None, motion=(track.start, track.log)) for t0, track in turns]
    pipe = ScanPipe()
    for job in jobs:
        pipe.submit(job)
    with pytest.raises(ValueError, match="already queued"):
        pipe.submit(jobs[-1])
    pipe.close()
    pipe.close()
    with pytest.raises(ValueError, match="closed"):
        pipe.submit(jobs[0])
    for (t0, track), job in zip(turns, jobs, strict=True):
        assert pipe.wait(job) is job
        want = lidar.scan_numpy(SANDBOX, track, t0)
        assert np.array_equal(job.ranges, want.ranges)
        assert np.allclose(np.stack(job.knots), np.stack(track.knots_numpy()), rtol=0, atol=1e-12)


def test_without_a_pipe_or_the_c_helper_a_started_scan_is_made_at_once(monkeypatch: pytest.MonkeyPatch
                                                                      ) -> None:
    t0, track = _turns(1)[0]
    want = Lidar().scan_numpy(SANDBOX, track, t0, np.random.default_rng(2))
    _same_scan(Lidar().start_scan(SANDBOX, track, t0, np.random.default_rng(2), None).result(), want)
    monkeypatch.setattr(raycast, "_lib", False)
    assert ScanPipe.open() is None
    world = World(SANDBOX.segments, SANDBOX.circles)
    _same_scan(Lidar().start_scan(world, track, t0, np.random.default_rng(2), None).result(), want)


def test_a_lidar_that_has_scanned_pickles() -> None:
    lidar = Lidar(mount=LidarMount(x=0.3))
    t0, track = _turns(1)[0]
    first = lidar.scan(SANDBOX, track, t0)
    copy = pickle.loads(pickle.dumps(lidar))
    assert copy == lidar and np.array_equal(copy.scan(SANDBOX, track, t0).ranges, first.ranges)
