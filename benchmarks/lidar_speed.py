"""The lidar's cost to the simulation, the figures of docs/benchmarks.md's "Lidar ray
cast" section, measured side by side in one run:

* the real-time factor of one drive of the stepped port + plant (``SteppedChair``, a
  CMDVEL every 0.2 s, 0.1 s at a time) with the lidar off; with an RPLidar S3 on (10
  Hz, 3,200 samples a turn published as 3,240 beams, each sample cast from the
  chair's pose at its own time: a ``MotionTrack`` of the plant's motion log), each
  turn made at once after its window (``Lidar.scan``); and with each turn made on a
  ``ScanPipe``'s C thread while the next window runs, collected after it
  (``Lidar.start_scan``; the wait makes what is left of the turn, so both cores work
  on it); on tb3_sandbox's map and on a hand-written room; the three alternate,
  ``--runs`` times each, medians;
* one turn's cost, best of several: the C cast of its 3,200 rays from a moving chair
  (``World.cast``: each ray walking the grid), with numpy (``World.cast_exact``) and
  with pymunk (``Space.segment_query_first`` per ray, static radius-0 segments and
  circles), how far each lands from the C cast; the whole ``Lidar.scan`` and its
  parts (the C turn with its poses integrated and its fan of direction bins, the
  same turn with each ray walking the grid, its noise drawn in C with numpy's own
  generator, the rest: Python), numpy's draws, and the reference
  ``Lidar.scan_numpy`` (numpy poses, noise and bins around ``World.cast``).

    python benchmarks/lidar_speed.py               # 30 simulated s, 5 runs each
    python benchmarks/lidar_speed.py --quick       # 10 s, 2 runs

* the same side by side on the scenario runner (``wcdrive.sim.runner.run``: the
  port, the host, the plant, with the lidar's turns made by ``ScanRecorder`` on a scan
  thread): the bundled ``corridor_lidar`` and ``room_lidar`` with their ``[lidar]``
  table and without it, and with each ray walking the grid, alternating, ``--runs``
  times each, medians (``--runner-only``: this part alone; ``--busy``: again with
  another process keeping one core busy).

The scan thread gains only where the machine's second core is free.
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pymunk

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wcdrive.plant.lidar import Lidar, LidarMount, MotionTrack, PendingScan  # noqa: E402
from wcdrive.plant.raycast import ScanJob, ScanPipe, draws_in_c  # noqa: E402
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
WORLDS = {"tb3_sandbox": (0.5, 0.3), "room": (0.0, 0.0), "tb3_sandbox_3x3": (0.5, 0.3)}
SPEED, TURN = 0.4, 0.5
LIDAR = Lidar(mount=LidarMount(x=0.30, z=0.45))


def worlds() -> dict[str, World]:
    """tb3_sandbox's outline, the room, and nine copies of the outline side by side (a
    world of more items than half a turn's samples: its turns walk the grid)."""
    sandbox = World.from_grid(load_map(ROOT / "tests" / "data" / "rosmaps" / "tb3_sandbox.yaml"))
    seg = sandbox.segments
    step = seg.max(axis=0)[:2] - seg.min(axis=0)[:2] + 0.5
    tiles = [seg + np.tile(step * (i, j), 2) for i in range(-1, 2) for j in range(-1, 2)]
    return {"tb3_sandbox": sandbox, "room": World.from_table(ROOM),
            "tb3_sandbox_3x3": World(np.concatenate(tiles), np.zeros((0, 3)))}


MODES = ("off", "on", "thread")


def drive(seconds: float, world: World | None, offset: tuple[float, float] = (0.0, 0.0),
          check: bool = False, pipe: ScanPipe | None = None) -> tuple[float, int, float]:
    """One drive, ``world`` None for the lidar off, with ``pipe`` each turn made on its
    thread: its real-time factor, the scans made and (``check``, which costs time) the
    largest gap (m) between the pose integrated from the log and the plant's at a
    turn's end."""
    chair = SteppedChair()
    chair.set_velocity(SPEED, TURN)
    chair.run(0.5)                              # off the start
    rng = np.random.default_rng(0)
    plant = chair.plant
    if world is not None:
        plant.start_motion_log()
    scans, drift = 0, 0.0
    pending: PendingScan | None = None
    windows = round(seconds * LIDAR.model.scan_hz)
    wall = time.perf_counter()
    for w in range(windows):
        if w % 2 == 0:
            chair.set_velocity(SPEED, TURN)
        start, t0 = plant.pose, plant.time
        chair.run(1.0 / LIDAR.model.scan_hz)
        if world is None:
            continue
        track = MotionTrack(start, t0, plant.take_motion_log(), offset)
        if pipe is None:
            scans += len(LIDAR.scan(world, track, t0, rng).ranges) > 0
        else:
            started = LIDAR.start_scan(world, track, t0, rng, pipe)
            if pending is not None:
                scans += len(pending.result().ranges) > 0
            pending = started
        if check:
            ex, ey, _ = track(np.array([plant.time]))
            x, y, _ = plant.pose
            drift = max(drift, math.hypot(ex[0] - offset[0] - x, ey[0] - offset[1] - y))
    if pending is not None:
        scans += len(pending.result().ranges) > 0
    wall = time.perf_counter() - wall
    return windows / LIDAR.model.scan_hz / wall, scans, drift


def rtf_side_by_side(seconds: float, runs: int) -> dict[str, dict[str, float]]:
    """Per world, the median real-time factor with the lidar off, on, and on with a
    scan thread (alternating)."""
    out = {}
    with ScanPipe() as pipe:
        for name, world in worlds().items():
            world.cast(np.zeros(2), np.zeros(1))    # the grid built before the clock starts
            drift = drive(3.0, world, WORLDS[name], check=True)[2]        # and a warm-up
            drive(3.0, world, WORLDS[name], pipe=pipe)
            rtf: dict[str, list[float]] = {mode: [] for mode in MODES}
            for _ in range(runs):
                rtf["off"].append(drive(seconds, None)[0])
                rtf["on"].append(drive(seconds, world, WORLDS[name])[0])
                rtf["thread"].append(drive(seconds, world, WORLDS[name], pipe=pipe)[0])
            out[name] = {mode: statistics.median(v) for mode, v in rtf.items()} | {"drift": drift}
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
    """ms for one turn: the cast in C, numpy and pymunk; ``Lidar.scan`` and its parts;
    ``Lidar.scan_numpy``."""
    origins, angles = one_turn(offset)
    c = world.cast(origins, angles, 40.0)
    exact = world.cast_exact(origins, angles, 40.0)
    pm = pymunk_cast(world, origins, angles)
    by_pymunk = pm()
    grid = world.ray_grid
    assert grid is not None
    steps = round(1e3 / LIDAR.model.scan_hz)
    log = np.zeros((steps, 6))
    log[:, 0] = np.arange(1, steps + 1) * 1e-3
    log[:, 1], log[:, 3] = SPEED, TURN
    track = MotionTrack((0.0, 0.0, 0.0), 0.0, log, offset)
    rng = np.random.default_rng(0)
    job = ScanJob(grid, LIDAR._turn, 0.0, rng.standard_normal(LIDAR.model.samples),
                  motion=(track.start, track.log))
    drawing = ScanJob(grid, LIDAR._turn, 0.0, None, motion=(track.start, track.log),
                      draw=rng) if draws_in_c() else job
    fan = grid.fan_bins

    def walk() -> None:
        grid.fan_bins = 0
        try:
            job.run()
        finally:
            grid.fan_bins = fan
    return {
        "segments": len(world.segments), "circles": len(world.circles),
        "cells": grid.shape[0] * grid.shape[1], "cell_m": grid.cell,
        "c_ms": _best_ms(lambda: world.cast(origins, angles, 40.0), 10 * repeat),
        "numpy_ms": _best_ms(lambda: world.cast_exact(origins, angles, 40.0), max(1, repeat // 2)),
        "pymunk_ms": _best_ms(pm, repeat),
        "scan_ms": _best_ms(lambda: LIDAR.scan(world, MotionTrack(track.start, 0.0, log), 0.0, rng),
                            10 * repeat),
        "noise_ms": _best_ms(lambda: rng.standard_normal(LIDAR.model.samples), 10 * repeat),
        "turn_ms": _best_ms(job.run, 10 * repeat),
        "walk_turn_ms": _best_ms(walk, 10 * repeat),
        "drawing_turn_ms": _best_ms(drawing.run, 10 * repeat),
        "reference_ms": _best_ms(lambda: LIDAR.scan_numpy(world, track, 0.0, rng), repeat),
        "numpy_gap": _gap(c, exact)[0], "numpy_bitwise": float(c.tobytes() == exact.tobytes()),
        "pymunk_gap": _gap(c, by_pymunk)[0], "pymunk_mismatch": _gap(c, by_pymunk)[1],
        "hits": int(np.isfinite(c).sum()),
    }


def runner_side_by_side(runs: int) -> dict[str, dict[str, float]]:
    """Per bundled lidar scenario: the runner's median real-time factor with the lidar
    off, on, and on with each ray walking the grid (no fan), alternating; the
    simulated seconds and the scans a run."""
    import dataclasses

    from wcdrive.sim import runner, scenario

    out = {}
    for name in ("corridor_lidar", "room_lidar"):
        sc = scenario.load(name)
        off = dataclasses.replace(sc, lidar=None)
        first = runner.run(sc)                                 # a warm-up (the grid built)
        grid = sc.world.ray_grid if sc.world is not None else None
        assert grid is not None and first.lidar is not None
        fan = grid.fan_bins
        rtf: dict[str, list[float]] = {"off": [], "on": [], "walk": []}
        for _ in range(runs):
            rtf["off"].append(runner.run(off).real_time_factor)
            rtf["on"].append(runner.run(sc).real_time_factor)
            grid.fan_bins = 0
            try:
                rtf["walk"].append(runner.run(sc).real_time_factor)
            finally:
                grid.fan_bins = fan
        out[name] = {mode: statistics.median(v) for mode, v in rtf.items()} | {
            "seconds": first.duration, "scans": float(len(first.lidar.scans))}
    return out


def _hog() -> subprocess.Popen[bytes]:
    """Another process keeping one core busy (as another developer's test run does)."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def print_runner(runs: int, busy: bool) -> None:
    for loaded in (False, True) if busy else (False,):
        hog = _hog() if loaded else None
        try:
            rows = runner_side_by_side(runs)
        finally:
            if hog is not None:
                hog.kill()
                hog.wait()
        where = "another process busy on one core" if loaded else "nothing else running"
        print(f"\nthe scenario runner (port, host, plant; the turns on a scan thread), {where}, "
              f"median of {runs}:")
        print("| scenario | simulated | scans | lidar off | on | on / off | the lidar per turn "
              "| on, no fan | on / off | the lidar per turn |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for name, r in rows.items():
            def per_turn(mode: str, r: dict[str, float] = r) -> float:
                return (r["seconds"] / r[mode] - r["seconds"] / r["off"]) / r["scans"] * 1e3
            print(f"| {name} | {r['seconds']:.1f} s | {r['scans']:.0f} | {r['off']:.0f}x | {r['on']:.0f}x "
                  f"| {r['on'] / r['off']:.3f} | {per_turn('on'):.3f} ms | {r['walk']:.0f}x "
                  f"| {r['walk'] / r['off']:.3f} | {per_turn('walk'):.3f} ms |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds a drive")
    ap.add_argument("--runs", type=int, default=5, help="drives each way, each world")
    ap.add_argument("--quick", action="store_true", help="10 s, 2 runs")
    ap.add_argument("--runner-only", action="store_true", help="only the scenario runner's side by side")
    ap.add_argument("--busy", action="store_true",
                    help="the runner's side by side also with another process busy on one core")
    args = ap.parse_args()
    seconds, runs = (10.0, 2) if args.quick else (args.seconds, args.runs)
    if args.runner_only:
        print_runner(runs, args.busy)
        return
    costs = {name: scan_cost(world, WORLDS[name], 3 if args.quick else 5) for name, world in worlds().items()}
    print("one S3 turn (3,200 rays from a moving chair), best of several:")
    print("| world | segments, circles | grid | C grid | numpy | pymunk "
          "| C vs numpy | C vs pymunk |")
    print("|---|---|---|---|---|---|---|---|")
    for name, c in costs.items():
        vs_numpy = "bit for bit" if c["numpy_bitwise"] else f"{c['numpy_gap']:.1e} m"
        print(f"| {name} | {c['segments']}, {c['circles']} | {c['cells']} cells of {c['cell_m']:.2f} m "
              f"| {c['c_ms']:.2f} ms | {c['numpy_ms']:.0f} ms | {c['pymunk_ms']:.1f} ms "
              f"| {vs_numpy} | {c['pymunk_gap']:.1e} m, "
              f"{c['pymunk_mismatch']} hit/miss differences ({c['hits']} hits) |")
    print("\nthe whole Lidar.scan of one turn and its parts (ms), best of several:")
    print("| world | Lidar.scan | C turn (poses, fan, casts, bins) | the same, each ray walking the grid "
          "| noise draws in C (numpy's own) | the rest (Python) | noise draws by numpy "
          "| Lidar.scan_numpy (its casts World.cast's) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, c in costs.items():
        draws = c["drawing_turn_ms"] - c["turn_ms"]
        rest = c["scan_ms"] - c["drawing_turn_ms"]
        print(f"| {name} | {c['scan_ms']:.3f} | {c['turn_ms']:.3f} | {c['walk_turn_ms']:.3f} | {draws:.3f} "
              f"| {rest:.3f} | {c['noise_ms']:.3f} | {c['reference_ms']:.2f} |")
    rtf = rtf_side_by_side(seconds, runs)
    print(f"\nreal-time factor, stepped port + plant, {seconds:g} s drives, median of {runs}:")
    print("| world | lidar off | on | on / off | lidar's ms per scan | on, scan thread | on / off "
          "| lidar's ms per scan | budget for on / off = 0.5 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in rtf.items():
        def per_scan(mode: str, r: dict[str, float] = r) -> float:
            return (1 / r[mode] - 1 / r["off"]) / LIDAR.model.scan_hz * 1e3
        budget = 1 / r["off"] / LIDAR.model.scan_hz * 1e3
        print(f"| {name} | {r['off']:.0f}x | {r['on']:.0f}x | {r['on'] / r['off']:.3f} "
              f"| {per_scan('on'):.2f} ms "
              f"| {r['thread']:.0f}x | {r['thread'] / r['off']:.3f} | {per_scan('thread'):.2f} ms "
              f"| {budget:.3f} ms |")
    drift = max(r["drift"] for r in rtf.values())
    print(f"(the pose integrated from the motion log is within {drift * 1e3:.2f} mm of the plant's at each "
          "turn's end)")
    print_runner(runs, args.busy)


if __name__ == "__main__":
    main()
