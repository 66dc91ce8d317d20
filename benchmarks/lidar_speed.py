"""The lidar's cost to the simulation, the figures of docs/benchmarks.md's "Lidar ray
cast" section, measured side by side in one run:

* the real-time factor of one drive of the stepped port + plant (``SteppedChair``, a
  CMDVEL every 0.2 s, 0.1 s at a time) with the lidar off, and with an RPLidar S3 on
  (10 Hz, 3,200 samples a turn published as 3,240 beams, each sample cast from the
  chair's pose at its own time: the plant's motion log of the turn, integrated from
  the pose at its start), on tb3_sandbox's map and on a hand-written room; off and on
  alternate, ``--runs`` times each, medians;
* one turn's cast (3,200 rays from a moving chair) with the C grid
  (``World.cast``), with numpy (``World.cast_exact``) and with pymunk
  (``Space.segment_query_first`` per ray, static radius-0 segments and circles): ms per
  scan, and how far each lands from the C cast.

    python benchmarks/lidar_speed.py               # 30 simulated s, 5 runs each
    python benchmarks/lidar_speed.py --quick       # 10 s, 2 runs
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pymunk

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wcdrive.plant.lidar import Lidar, LidarMount, PoseAt  # noqa: E402
from wcdrive.plant.rosmap import load_map  # noqa: E402
from wcdrive.plant.world import World  # noqa: E402
from wcdrive.testing.stepped import SteppedChair  # noqa: E402

#: A furnished room: 8 x 6 m, a partition with a doorway, a bed, a wardrobe, a table
#: on four legs, a post.
ROOM = {
    "walls": [[-3, -2.5, 5, -2.5, 5, 3.5, -3, 3.5, -3, -2.5], [1.5, 3.5, 1.5, 1.8], [1.5, 0.9, 1.5, -0.4]],
    "boxes": [[3.6, 2.4, 2.0, 1.4], [-2.4, 2.6, 1.0, 0.6, 10], [-0.2, 3.1, 1.2, 0.5]],
    "circles": [[2.6, -1.6, 0.03], [3.4, -1.6, 0.03], [2.6, -1.0, 0.03], [3.4, -1.0, 0.03],
                [-1.5, -1.5, 0.15]],
}
#: Where the chair starts in each world (its own frame starts at 0, 0, 0), and the drive:
#: a circle of 0.8 m radius at 0.4 m/s.
WORLDS = {"tb3_sandbox": (0.5, 0.3), "room": (0.0, 0.0)}
SPEED, TURN = 0.4, 0.5
LIDAR = Lidar(mount=LidarMount(x=0.30, z=0.45))


def worlds() -> dict[str, World]:
    sandbox = load_map(ROOT / "tests" / "data" / "rosmaps" / "tb3_sandbox.yaml")
    return {"tb3_sandbox": World.from_grid(sandbox), "room": World.from_table(ROOM)}


def log_pose_at(start: tuple[float, float, float], t0: float, log: np.ndarray, offset: tuple[float, float]
                ) -> PoseAt:
    """The chair's pose at any time of a turn from the pose at its start and the plant's
    motion log of its steps (time, forward, lateral, yaw rate, ...), in the world's frame
    (the chair's start at ``offset``)."""
    t = np.concatenate(([t0], log[:, 0]))
    dt = np.diff(t)
    heading = start[2] + np.concatenate(([0.0], np.cumsum(log[:, 3] * dt)))
    mid = heading[1:] - log[:, 3] * dt / 2
    c, s = np.cos(mid), np.sin(mid)
    x = start[0] + offset[0] + np.concatenate(([0.0], np.cumsum((log[:, 1] * c - log[:, 2] * s) * dt)))
    y = start[1] + offset[1] + np.concatenate(([0.0], np.cumsum((log[:, 1] * s + log[:, 2] * c) * dt)))

    def pose_at(times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.interp(times, t, x), np.interp(times, t, y), np.interp(times, t, heading)
    return pose_at


def drive(seconds: float, world: World | None, offset: tuple[float, float] = (0.0, 0.0),
          check: bool = False) -> tuple[float, int, float]:
    """One drive, ``world`` None for the lidar off: its real-time factor, the scans made
    and (``check``, which costs time) the largest gap (m) between the pose integrated
    from the log and the plant's at a turn's end."""
    chair = SteppedChair()
    chair.set_velocity(SPEED, TURN)
    chair.run(0.5)                              # off the start
    rng = np.random.default_rng(0)
    plant = chair.plant
    if world is not None:
        plant.start_motion_log()
    scans, drift = 0, 0.0
    windows = round(seconds * LIDAR.model.scan_hz)
    wall = time.perf_counter()
    for w in range(windows):
        if w % 2 == 0:
            chair.set_velocity(SPEED, TURN)
        start, t0 = plant.pose, plant.time
        chair.run(1.0 / LIDAR.model.scan_hz)
        if world is not None:
            pose_at = log_pose_at(start, t0, plant.take_motion_log(), offset)
            scan = LIDAR.scan(world, pose_at, t0, rng)
            scans += len(scan.ranges) > 0
            if not check:
                continue
            ex, ey, _ = pose_at(np.array([plant.time]))
            x, y, _ = plant.pose
            drift = max(drift, math.hypot(ex[0] - offset[0] - x, ey[0] - offset[1] - y))
    wall = time.perf_counter() - wall
    return windows / LIDAR.model.scan_hz / wall, scans, drift


def rtf_side_by_side(seconds: float, runs: int) -> dict[str, dict[str, float]]:
    """Per world, the median real-time factor with the lidar off and on (alternating)."""
    out = {}
    for name, world in worlds().items():
        world.cast(np.zeros(2), np.zeros(1))    # the grid built before the clock starts
        drift = drive(3.0, world, WORLDS[name], check=True)[2]        # and a warm-up
        off, on = [], []
        for _ in range(runs):
            off.append(drive(seconds, None)[0])
            on.append(drive(seconds, world, WORLDS[name])[0])
        out[name] = {"off": statistics.median(off), "on": statistics.median(on), "drift": drift}
    return out


def _best_ms(f: Callable[[], object], repeat: int) -> float:
    f()
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t)
    return best * 1e3


def one_turn(offset: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The origins and directions of one turn's 3,200 samples, the chair at 0.4 m/s on
    its circle, starting at ``offset``."""
    m = LIDAR.model
    times = np.arange(m.samples) / m.sample_hz
    heading = TURN * times
    x = offset[0] + SPEED / TURN * np.sin(heading)
    y = offset[1] + SPEED / TURN * (1 - np.cos(heading))
    device = np.radians(np.arange(m.samples) * 360.0 / m.samples)
    origins = np.column_stack((x + LIDAR.mount.x * np.cos(heading), y + LIDAR.mount.x * np.sin(heading)))
    return origins, heading + math.pi - device


def pymunk_cast(world: World, origins: np.ndarray, angles: np.ndarray, length: float = 40.0
                ) -> Callable[[], np.ndarray]:
    space = pymunk.Space()
    body = space.static_body
    space.add(*[pymunk.Segment(body, (s[0], s[1]), (s[2], s[3]), 0.0) for s in world.segments])
    space.add(*[pymunk.Circle(body, c[2], (c[0], c[1])) for c in world.circles])
    ends = origins + length * np.column_stack((np.cos(angles), np.sin(angles)))
    rays = list(zip(origins.tolist(), ends.tolist(), strict=True))
    everything = pymunk.ShapeFilter()

    def cast() -> np.ndarray:
        out = np.full(len(rays), math.inf)
        for i, (a, b) in enumerate(rays):
            hit = space.segment_query_first(a, b, 0.0, everything)
            if hit is not None:
                out[i] = hit.alpha * length
        return out
    return cast


def _gap(a: np.ndarray, b: np.ndarray) -> tuple[float, int]:
    """The largest difference where both hit, and the rays where one hits and one not."""
    both = np.isfinite(a) & np.isfinite(b)
    return float(np.abs(a[both] - b[both]).max(initial=0.0)), int((np.isfinite(a) != np.isfinite(b)).sum())


def scan_cost(world: World, offset: tuple[float, float], repeat: int) -> dict[str, float]:
    """ms for one turn's cast: C, numpy, pymunk; and the whole ``Lidar.scan``."""
    origins, angles = one_turn(offset)
    c = world.cast(origins, angles, 40.0)
    exact = world.cast_exact(origins, angles, 40.0)
    pm = pymunk_cast(world, origins, angles)
    by_pymunk = pm()
    grid = world.__dict__["_ray_grid"]
    moving = log_pose_at((0.0, 0.0, 0.0), 0.0, np.array([[0.1, SPEED, 0.0, TURN, 0.0, 0.0]]), offset)
    rng = np.random.default_rng(0)
    return {
        "segments": len(world.segments), "circles": len(world.circles),
        "cells": grid.shape[0] * grid.shape[1], "cell_m": grid.cell,
        "c_ms": _best_ms(lambda: world.cast(origins, angles, 40.0), 10 * repeat),
        "numpy_ms": _best_ms(lambda: world.cast_exact(origins, angles, 40.0), max(1, repeat // 2)),
        "pymunk_ms": _best_ms(pm, repeat),
        "scan_ms": _best_ms(lambda: LIDAR.scan(world, moving, 0.0, rng), 10 * repeat),
        "numpy_gap": _gap(c, exact)[0], "numpy_bitwise": float(c.tobytes() == exact.tobytes()),
        "pymunk_gap": _gap(c, by_pymunk)[0], "pymunk_mismatch": _gap(c, by_pymunk)[1],
        "hits": int(np.isfinite(c).sum()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds a drive")
    ap.add_argument("--runs", type=int, default=5, help="drives each way, each world")
    ap.add_argument("--quick", action="store_true", help="10 s, 2 runs")
    args = ap.parse_args()
    seconds, runs = (10.0, 2) if args.quick else (args.seconds, args.runs)
    costs = {name: scan_cost(world, WORLDS[name], 3 if args.quick else 5) for name, world in worlds().items()}
    print("one S3 turn (3,200 rays from a moving chair), best of several:")
    print("| world | segments, circles | grid | C grid | numpy | pymunk | whole Lidar.scan (C) "
          "| C vs numpy | C vs pymunk |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, c in costs.items():
        vs_numpy = "bit for bit" if c["numpy_bitwise"] else f"{c['numpy_gap']:.1e} m"
        print(f"| {name} | {c['segments']}, {c['circles']} | {c['cells']} cells of {c['cell_m']:.2f} m "
              f"| {c['c_ms']:.2f} ms | {c['numpy_ms']:.0f} ms | {c['pymunk_ms']:.1f} ms "
              f"| {c['scan_ms']:.2f} ms | {vs_numpy} | {c['pymunk_gap']:.1e} m, "
              f"{c['pymunk_mismatch']} hit/miss differences ({c['hits']} hits) |")
    rtf = rtf_side_by_side(seconds, runs)
    print(f"\nreal-time factor, stepped port + plant, {seconds:g} s drives, median of {runs}:")
    print("| world | lidar off | lidar on | on / off | lidar's ms per scan | budget for on / off = 0.5 |")
    print("|---|---|---|---|---|---|")
    for name, r in rtf.items():
        per_scan = (1 / r["on"] - 1 / r["off"]) / LIDAR.model.scan_hz * 1e3
        budget = 1 / r["off"] / LIDAR.model.scan_hz * 1e3
        print(f"| {name} | {r['off']:.0f}x | {r['on']:.0f}x | {r['on'] / r['off']:.3f} | {per_scan:.2f} ms "
              f"| {budget:.3f} ms |")
    drift = max(r["drift"] for r in rtf.values())
    print(f"(the pose integrated from the motion log is within {drift * 1e3:.2f} mm of the plant's at each "
          "turn's end)")


if __name__ == "__main__":
    main()
