"""``wcdrive sim --robot eddie SCENARIO``: the bundled scenarios on the simulated Eddie.

Deterministic, no threads, simulated time only: ``EddieLoop`` (the board model and the
Eddie plant) and, as the host, what ``EddieRobot`` does: a scenario's ``cmdvel`` (and
``wheel``, in rad/s) becomes ``GOSPD`` (sent when the pair changes), ``stop`` is
``GOSPD 0 0``, ``silence`` sends nothing and the host deadman sends ``STOP 0`` 0.5 s
after the last command while moving; ``DIST`` is polled at 25 Hz and integrated by
``WheelOdometry``. Compared with the plant's ground truth at every poll: the
odometry's error at the end and the largest along the way.

What does not carry over from the Mega's scenarios, and is reported, not faked:
``ppm`` segments (no RC input on Eddie: silence), ``[[fault]]`` and ``[params]`` (the
Mega's), ``[chair]`` (the Mega's ChairParams; Eddie's come from ``[eddie]``, e.g.
``wheel_separation = 0.3``), ``[world]``'s floor grades (Eddie drives on the flat),
``[lidar]`` (Eddie has none). A scenario may place walls for the range sensors:
``[[wall]]`` tables with ``a = [x, y]`` and ``b = [x, y]`` in metres, and the
``[world]`` table's ``map``, ``walls``, ``boxes``, ``circles`` and ``file``
(``wcdrive.plant.world``), which the PING))) and IR sensors see through the world's
ray cast; its ``start`` places Eddie (the odometry starts at its own 0, 0, 0 and is
compared placed at the start). Neither kind of wall stops Eddie's chassis: only the
sensors' rays.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pymunk

from wcdrive.eddie.board import EddieLoop, Wall
from wcdrive.eddie.geometry import PING_MOUNTS, POSITIONS_PER_REV, WHEEL_RADIUS
from wcdrive.eddie.plant import eddie_params
from wcdrive.eddie.robot import PING_M_PER_UNIT, RAD_PER_POSITION, gospd_counts, signed, std_hex
from wcdrive.host.odometry import OdometryParams, WheelOdometry
from wcdrive.sim import scenario
from wcdrive.sim.contract import Miss, evaluate
from wcdrive.sim.scenario import Scenario, ScenarioError

#: Eddie's own scenarios (walls), found by name after the bundled ones.
SCENARIOS = Path(__file__).resolve().parent / "scenarios"
#: The top-level tables Eddie reads from a scenario besides the Mega's: walls, overrides.
EDDIE_KEYS = ("wall", "eddie")
POLL_HZ = 25.0
DEADMAN_S = 0.5


@dataclass
class EddieResult:
    """One scenario on Eddie: the final poses and the odometry's errors."""

    name: str
    duration: float
    truth: tuple[float, float, float]
    odometry: tuple[float, float, float]
    final_error_m: float
    final_heading_error_deg: float
    max_error_m: float
    path_length_m: float
    deadman_stops: int
    #: The nearest PING))) reading (m) and the sensor's true distance to a wall then
    #: (polled at 5 Hz; None without an echo all along).
    nearest_ping: tuple[float, float] | None = None
    notes: list[str] = field(default_factory=list)


def load(name: str) -> Scenario:
    """A bundled scenario, one of Eddie's own (``wcdrive/eddie/scenarios``), or a path."""
    try:
        return scenario.load(name, extra=EDDIE_KEYS)
    except ScenarioError:
        own = SCENARIOS / f"{name}.toml"
        if own.exists():
            return scenario.load(str(own), extra=EDDIE_KEYS)
        raise


def _extras(sc: Scenario) -> tuple[list[Wall], dict[str, float]]:
    if sc.source is None:
        return [], {}
    data = tomllib.loads(sc.source.read_text())
    walls: list[Wall] = []
    for i, raw in enumerate(data.get("wall", [])):
        try:
            a, b = raw["a"], raw["b"]
            walls.append(((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))))
        except (KeyError, TypeError, IndexError, ValueError) as exc:
            raise ScenarioError(f"{sc.source}: wall {i + 1} needs a = [x, y] and b = [x, y]") from exc
    return walls, {k: float(v) for k, v in data.get("eddie", {}).items()}


def _command(kind: str, values: tuple[float, ...], separation: float) -> tuple[int, int] | None:
    if kind == "cmdvel":
        return gospd_counts(values[0], values[1], separation)
    if kind == "wheel":                              # [right, left] in rad/s
        return math.trunc(values[1] / RAD_PER_POSITION), math.trunc(values[0] / RAD_PER_POSITION)
    if kind == "stop":
        return (0, 0)
    return None


def run(sc: Scenario, *, seed: int = 0) -> EddieResult:
    """Runs ``sc`` on the simulated Eddie (module docstring)."""
    walls, overrides = _extras(sc)
    params = eddie_params(**overrides)
    loop = EddieLoop(params, walls=walls, seed=seed, world=sc.world, start=sc.start)
    odo = WheelOdometry(OdometryParams(wheel_radius=WHEEL_RADIUS, wheelbase=params.wheelbase,
                                       counts_per_rev=POSITIONS_PER_REV))
    notes = sorted({f"{s.kind} segments are silence on Eddie" for s in sc.segments if s.kind == "ppm"})
    if sc.faults:
        notes.append("[[fault]] not modelled on Eddie: ignored")
    if sc.board_params:
        notes.append("[params] are the Mega's: ignored")
    if sc.chair:
        notes.append("[chair] is the Mega's ChairParams: ignored (Eddie's: [eddie])")
    if not sc.terrain.flat:
        notes.append("[world] grades not modelled on Eddie: a flat floor")
    if sc.lidar is not None:
        notes.append("[lidar] not on Eddie: ignored")
    # the host's timeline: (time, command pair or None for silence)
    plan: list[tuple[float, tuple[int, int] | None]] = []
    t = 0.02
    period = 1.0 / sc.host_rate_hz
    for seg in sc.segments:
        pair = _command(seg.kind, seg.values, params.wheelbase)
        n = max(1, round(seg.duration / period))
        plan += [(t + k * period, pair) for k in range(n)] if pair is not None else []
        t += seg.duration
    plan.append((t, (0, 0)))
    end = sc.duration
    sent: tuple[int, int] | None = None
    last_command = 0.0
    deadman = 0
    next_poll = 0.0
    max_error = 0.0
    path = 0.0
    prev = loop.plant.pose
    loop.send(b"RST\r")
    i = 0
    polls = 0
    nearest: tuple[float, float] | None = None
    for k in range(1, math.ceil(end / 0.005) + 1):
        step_end = k * 0.005
        while i < len(plan) and plan[i][0] <= step_end:
            when, pair = plan[i]
            loop.run_until(when)
            last_command = when
            if pair is not None and pair != sent:
                loop.send(f"GOSPD {std_hex(pair[0])} {std_hex(pair[1])}\r".encode())
                sent = pair
            i += 1
        if sent not in (None, (0, 0)) and loop.time - last_command > DEADMAN_S:
            loop.send(b"STOP 0\r")
            sent = None
            deadman += 1
        if loop.time >= next_poll:
            loop.send(b"DIST\r")
            polls += 1
            if (walls or sc.world is not None) and polls % 5 == 0:
                loop.send(b"PING\r")
            next_poll += 1.0 / POLL_HZ
        loop.run_until(step_end)
        for when, data in loop.take_output():
            for line in data.split(b"\r"):
                if len(line) == 17:
                    left, right = signed(line[0:8].decode(), 32), signed(line[9:17].decode(), 32)
                    est = odo.update(when, -left, right)
                    x, y, _ = loop.plant.pose
                    ex, ey, _ = _placed(sc.start, (est.pose.x, est.pose.y, est.pose.theta))
                    max_error = max(max_error, math.hypot(ex - x, ey - y))
                elif len(line) == 15 and line.count(b" ") == 3:      # PING: four 3-digit values
                    values = [int(v, 16) * PING_M_PER_UNIT for v in line.split() if int(v, 16)]
                    if values and (nearest is None or min(values) < nearest[0]):
                        nearest = (min(values), _true_ping(loop))
        pose = loop.plant.pose
        path += math.hypot(pose[0] - prev[0], pose[1] - prev[1])
        prev = pose
    x, y, th = loop.plant.pose
    ox, oy, oth = _placed(sc.start, (odo.pose.x, odo.pose.y, odo.pose.theta))
    return EddieResult(
        name=sc.name, duration=end, truth=(x, y, th), odometry=(ox, oy, oth),
        final_error_m=math.hypot(ox - x, oy - y),
        final_heading_error_deg=abs(math.degrees(math.remainder(oth - th, 2 * math.pi))),
        max_error_m=max_error, path_length_m=path, deadman_stops=deadman, nearest_ping=nearest,
        notes=notes)


Pose = tuple[float, float, float]


def _placed(start: Pose, pose: Pose) -> Pose:
    """An odometry pose (from its own 0, 0, 0) in the map frame of a start at ``start``."""
    x0, y0, th0 = start
    c, s = math.cos(th0), math.sin(th0)
    return x0 + c * pose[0] - s * pose[1], y0 + s * pose[0] + c * pose[1], pose[2] + th0


def _true_ping(loop: EddieLoop) -> float:
    """The nearest wall (``[[wall]]`` or ``[world]``) straight ahead of the PING)))
    sensors, noise-free (m)."""
    x, y, th = loop.plant.pose
    best = math.inf
    world = loop.sensors.world
    for mount in PING_MOUNTS.values():
        ox = x + mount.ahead * math.cos(th) - mount.left * math.sin(th)
        oy = y + mount.ahead * math.sin(th) + mount.left * math.cos(th)
        far = (ox + 5 * math.cos(th), oy + 5 * math.sin(th))
        hit = loop.plant.space.segment_query_first((ox, oy), far, 0.0, pymunk.ShapeFilter())
        if hit is not None:
            best = min(best, hit.alpha * 5)
        if world is not None:
            best = min(best, float(world.cast_exact(np.array([ox, oy]), np.array([th]), 5.0)[0]))
    return best


def table(r: EddieResult) -> str:
    """A human-readable summary of one result."""
    lines = [f"{r.name} on Eddie ({r.duration:.1f} s simulated, {r.path_length_m:.2f} m driven)",
             f"  ground truth  x={r.truth[0]:+.3f} m  y={r.truth[1]:+.3f} m  "
             f"heading={math.degrees(r.truth[2]):+.1f} deg",
             f"  odometry      x={r.odometry[0]:+.3f} m  y={r.odometry[1]:+.3f} m  "
             f"heading={math.degrees(r.odometry[2]):+.1f} deg",
             f"  odometry error: final {r.final_error_m * 1000:.0f} mm, {r.final_heading_error_deg:.2f} deg; "
             f"largest {r.max_error_m * 1000:.0f} mm; host deadman stops: {r.deadman_stops}"]
    if r.nearest_ping is not None:
        lines.append(f"  nearest PING))) reading {r.nearest_ping[0]:.3f} m "
                     f"(the wall was {r.nearest_ping[1]:.3f} m straight ahead)")
    lines += [f"  note: {n}" for n in r.notes]
    return "\n".join(lines)


def figures(r: EddieResult) -> dict[str, object]:
    """The figures an Eddie scenario's ``[expect]`` bounds name (``wcdrive.sim.expect``):
    ``path_length_m``, ``final_error_m``, ``final_heading_error_deg``, ``max_error_m``,
    ``deadman_stops``, and from the nearest PING))) reading, ``nearest_ping_m``, the
    sensor's true distance then, ``nearest_ping_true_m``, and the reading's error,
    ``ping_error_m`` (the three None without an echo)."""
    ping = r.nearest_ping
    return {"path_length_m": r.path_length_m, "final_error_m": r.final_error_m,
            "final_heading_error_deg": r.final_heading_error_deg, "max_error_m": r.max_error_m,
            "deadman_stops": r.deadman_stops,
            "nearest_ping_m": None if ping is None else ping[0],
            "nearest_ping_true_m": None if ping is None else ping[1],
            "ping_error_m": None if ping is None else abs(ping[0] - ping[1])}


def check(sc: Scenario, r: EddieResult) -> list[Miss]:
    """The misses of ``r`` (a run of ``sc`` on Eddie) against ``sc``'s ``[expect]``
    table (``wcdrive.sim.contract.evaluate`` on ``figures``: Eddie reports no events);
    one miss when it has none."""
    if sc.expect is None:
        return [Miss(sc.name, "eddie", "[expect]", "the scenario has no [expect] table: nothing to check")]
    misses = evaluate(sc.expect, figures(r), None, name=sc.name, backend="eddie")
    if sc.expect.stops or sc.expect.safety:
        misses.append(Miss(sc.name, "eddie", "[expect]", "[[expect.stop]] and safety are the Mega's: "
                                                         "Eddie's runs have neither"))
    return misses


def to_json(results: list[EddieResult]) -> str:
    """Every result as JSON."""
    return json.dumps([asdict(r) for r in results], indent=2)
