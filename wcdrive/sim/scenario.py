"""Scenarios: plain TOML files of what the host sends, segment by segment.

    name = "square"
    description = "..."
    host_rate_hz = 10        # the host re-sends its current command this often
    repeat = 4               # the segment list, this many times (default 1)
    settle_s = 1.5           # after the last segment: a stop, then this long (default)
    neutral_first = true     # a neutral command before the first segment (default; the
                             #   board drives only after one: false shows it refusing)
    host_offset_s = 0.0      # the host's bytes this much later (0 to 1 s): its phase
                             #   against the board's 50 ms ticks (default 0)
    [chair]                  # optional ChairParams overrides, e.g. friction_left = 0.1
    [params]                 # optional runtime parameters the host sets first,
    watchdog_ms = 1000       #    set:<name>=<value> (protocol v2), e.g. kp_l, estop_decel
    [[segment]]
    cmdvel = [0.3, 0.0]      # or wheel = [right, left], ppm = [8 channels],
    duration = 3.33          #    stop = true, silence = true (the host sends nothing)
    [[fault]]                # optional, any number (wcdrive.plant.faults)
    at = 2.0                 # s from the start
    kind = "encoder_cut"     # encoder_cut | encoder_reversed | encoder_noise |
                             #   wheel_locked | motor_dead | brake_open | brake_short |
                             #   reset | link_cut
    side = "left"            # left | right | both (encoder, wheel and motor kinds)
    duration = 3.0           # optional: to the end of the scenario
    rate_hz = 200000         # encoder_noise: edges per second on channel A
    [[input]]                # optional, any number (wcdrive.sim.scenario_inputs)
    at = 3.0                 # s from the start
    input = "charger"        # the inhibit input: "charger" (1), "seat" (2), or "push" (4:
                             #   the brake's manual-release lever, pulled on the plant)
    active = true            # pulled LOW, or released (false); each starts released

The floor is level unless a ``[world]`` table tilts it (``wcdrive.plant.terrain``):

    [world]
    slope_deg = 0.0          # uniform grade (degrees, |slope| < 30; negative: rises)
    downhill_heading_deg = 0 # world heading the floor falls toward (0 = +x)
    [[world.ramp]]           # any number: a band of the floor with a grade of its own
    from_x = 1.0             # m along downhill_heading_deg where the band starts
    to_x = 3.0               # m where it ends (the floor outside has slope_deg)
    slope_deg = -6.0

The same table gives the walls the chair drives among, and where it starts
(``wcdrive.plant.world``, ``wcdrive.plant.chair``; all in the map frame):

    [world]
    map = "worlds/corridor.yaml"        # a ROS map_server YAML, relative to this file
    walls = [[0, 0, 10, 0, 10, 5]]      # polylines [x0, y0, x1, y1, ...]
    boxes = [[4, 2, 0.8, 0.6, 30]]      # [cx, cy, width, height(, yaw_deg)]
    circles = [[6, 1, 0.03]]            # [x, y, radius]: table legs, posts
    start = [1.0, 2.0, 90]              # the axle midpoint's x, y (m) and heading (deg)

A hand-written world can also live in a TOML file of its own (the bundled
``worlds/furnished_room.toml``), with the same ``walls``, ``boxes``, ``circles`` and
``map`` keys at its top level (its ``map`` relative to that file):

    [world]
    file = "worlds/furnished_room.toml" # relative to this file; joins the keys above

Any of ``file``, ``map``, ``walls``, ``boxes`` and ``circles`` may be given, together too; the
chair collides with what they make, and a footprint that overlaps it at ``start`` is a
ScenarioError. ``start`` (default ``[0, 0, 0]``) places the chair; the host's odometry
still starts at its own (0, 0, 0), and a ``path``'s waypoints are in that odometry
frame. The floor's grades (``slope_deg``, ramps) are in the map frame.

A ``[lidar]`` table puts a lidar on the chair (``wcdrive.plant.lidar``); without one
there is none. The run takes a scan every turn of its head from the start on, each
beam cast at its own time from where the chair then is (``SimResult.lidar``):

    [lidar]
    model = "rplidar_s3"     # the only model (MODELS in wcdrive.plant.lidar)
    x = 0.20                 # the mount in the chair's base frame (m, deg): the seed's
    y = 0.0                  #   static transform base_link -> laser (these defaults)
    z = 0.30
    yaw_deg = 0.0
    roll_deg = 0.0           # 180: mounted head down (the seed's chair); 0 or 180
    driver_inverted = false  # the driver's ``inverted`` parameter (told of the roll)

An ``[expect]`` table says what a run must show (``wcdrive.sim.expect``; ``wcdrive sim
NAME --check`` holds a run to it).

Every table's keys are checked: an unknown key, at the top level too, is a ScenarioError
that names it.

A closed-loop scenario gives a path instead of segments; the host follows it with a
pure-pursuit controller (``wcdrive.navigation.pure_pursuit``) against its own odometry, sending a
``cmdvel`` at ``host_rate_hz``:

    path = [[1.0, 0.0], [1.0, 1.0]]   # waypoints (m) in the odometry frame, from (0, 0)
    [follow]                 # optional, these are the defaults
    speed = 0.3              # m/s cruise
    lookahead = 0.35         # m
    max_angular = 0.6        # rad/s
    goal_tolerance = 0.05    # m: the host stops when its odometry is this close
    timeout_s = 60           # the run ends here if the goal is not reached
    localization = "wheel"   # or "ekf": the seeds' EKF on wheel velocities and the gyro
    truth_tolerance = 0.15   # m: the published bound on the true final position's error

Faults act the same way on both backends of ``wcdrive.sim.runner``: the encoder kinds on
the encoder's wire, ``wheel_locked`` and ``motor_dead`` on the plant, ``reset`` on the
board, and ``link_cut`` on the host's bytes, which stop reaching the board from ``at``
(mid-line if that is where it falls).

Bundled scenarios live in ``wcdrive/sim/scenarios``; ``wcdrive sim --list`` shows them and
any path to a file of your own works the same.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path

from wcdrive.boards.inhibits import InhibitChange
from wcdrive.errors import WcdriveFileError
from wcdrive.navigation.pure_pursuit import FollowParams
from wcdrive.plant.chair import Plant
from wcdrive.plant.faults import FAULT_KINDS, SIDED_KINDS, Fault
from wcdrive.plant.lidar import MODELS, SEED_MOUNT, Lidar, LidarMount
from wcdrive.plant.params import ChairParams
from wcdrive.plant.rosmap import MapFileError
from wcdrive.plant.terrain import Ramp, Terrain
from wcdrive.plant.world import World, WorldError
from wcdrive.protocol.codec import encode_ppm, encode_set
from wcdrive.protocol.motion import velocity_command, wheel_command
from wcdrive.sim.expect import Expect
from wcdrive.sim.expect import parse as parse_expect
from wcdrive.sim.scenario_inputs import parse_inputs

BUNDLED = Path(__file__).resolve().parent / "scenarios"
#: When a scenario's host sends its neutral command: the board refuses motion after a
#: boot until a neutral command has stood NEUTRAL_TICKS ticks (docs/safety.md).
NEUTRAL_AT_S = 0.008
#: When its first motion command goes out: the neutral confirmed by then (two ticks,
#: 100 ms), and 20 ms into a tick as the first command was before the neutral came (the
#: bundled scenarios' commands keep their phase against the board's 50 ms ticks, so the
#: figures measured before stay comparable).
MOTION_START_S = 0.17
_KINDS = ("cmdvel", "wheel", "ppm", "stop", "silence")
_FAULT_KEYS = ("at", "kind", "side", "duration", "rate_hz")
#: The keys a scenario file may have at its top level.
TOP_KEYS = ("name", "description", "host_rate_hz", "repeat", "settle_s", "neutral_first", "host_offset_s",
            "chair", "params",
            "segment", "fault", "input", "path", "follow", "world", "lidar", "expect")
_GEOMETRY_KEYS = ("map", "walls", "boxes", "circles")
_LIDAR_KEYS = ("model", "x", "y", "z", "yaw_deg", "roll_deg", "driver_inverted")
_WORLD_KEYS = ("slope_deg", "downhill_heading_deg", "ramp", *_GEOMETRY_KEYS, "file", "start")
_RAMP_KEYS = ("from_x", "to_x", "slope_deg")


class ScenarioError(WcdriveFileError):
    """A scenario file is missing or malformed; the message names the field."""


@dataclass(frozen=True)
class Segment:
    """One ``[[segment]]``: its kind (cmdvel, wheel, ppm, stop, silence), the values
    and the duration in s."""

    kind: str
    values: tuple[float, ...]
    duration: float

    def command(self) -> bytes | None:
        """The command the host repeats during the segment (None: it sends nothing)."""
        if self.kind == "cmdvel":
            return velocity_command(*self.values)
        if self.kind == "wheel":               # the file's order is the wire's: [right, left]
            right, left = self.values
            return wheel_command(left=left, right=right)
        if self.kind == "ppm":
            return encode_ppm([int(v) for v in self.values])
        if self.kind == "stop":
            return velocity_command(0.0, 0.0)
        return None


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario file (the module docstring), ``segments`` already repeated."""

    name: str
    description: str
    segments: tuple[Segment, ...]
    host_rate_hz: float = 10.0
    settle_s: float = 1.5
    #: The host sends a neutral command first (``NEUTRAL_AT_S``), its first segment from
    #: ``MOTION_START_S``; False: its first segment from 20 ms, with no neutral before it.
    neutral_first: bool = True
    #: s: every byte of the host this much later (its phase against the board's ticks).
    host_offset_s: float = 0.0
    chair: dict[str, float] = field(default_factory=dict)
    source: Path | None = None
    faults: tuple[Fault, ...] = ()
    board_params: dict[str, float] = field(default_factory=dict)
    #: A closed-loop scenario's waypoints (m) and how the host follows them; None: open loop.
    path: tuple[tuple[float, float], ...] | None = None
    follow: FollowParams = field(default_factory=FollowParams)
    #: The floor (``[world]``); flat without one.
    terrain: Terrain = field(default_factory=Terrain)
    #: The walls (``[world]``'s map, walls, boxes, circles); None: none.
    world: World | None = None
    #: The chair's start pose in the map frame: x, y (m), heading (rad).
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: The lidar on the chair (``[lidar]``); None: none.
    lidar: Lidar | None = None
    #: What a run must show (``[expect]``, ``wcdrive.sim.expect``); None: no table.
    expect: Expect | None = None
    #: The inhibit inputs' timeline (``[[input]]``, ``wcdrive.sim.scenario_inputs``).
    inhibits: tuple[InhibitChange, ...] = ()

    @property
    def closed_loop(self) -> bool:
        """True for a ``path`` scenario: the host steers by its odometry."""
        return self.path is not None

    @property
    def duration(self) -> float:
        """Seconds simulated at most: every segment, then ``settle_s`` (closed loop:
        ``timeout_s``, then ``settle_s``)."""
        if self.path is not None:
            return self.follow.timeout_s + self.settle_s
        return self.host_offset_s + sum(s.duration for s in self.segments) + self.settle_s

    def params(self) -> ChairParams:
        """``ChairParams`` with the scenario's ``[chair]`` overrides."""
        return dataclasses.replace(ChairParams(), **self.chair)  # type: ignore[arg-type]

    @property
    def segments_start(self) -> float:
        """s: when the first segment's command goes out (``MOTION_START_S``; 20 ms
        without ``neutral_first``; ``host_offset_s`` later); each segment starts where
        the one before ends."""
        return self.host_offset_s + (MOTION_START_S if self.neutral_first else 0.02)

    def host_commands(self) -> list[tuple[float, bytes]]:
        """(time, bytes) the host sends: the ``[params]`` settings at 5 ms, a neutral
        command at ``NEUTRAL_AT_S`` (the board drives only after one; ``neutral_first``),
        then each segment's command at ``host_rate_hz`` from ``MOTION_START_S`` (20 ms
        without the neutral), then a stop."""
        out: list[tuple[float, bytes]] = [(self.host_offset_s + 0.005, encode_set(name, value) + b"\n")
                                          for name, value in self.board_params.items()]
        if self.neutral_first:
            out.append((self.host_offset_s + NEUTRAL_AT_S, velocity_command(0.0, 0.0)))
        t0 = self.segments_start
        period = 1.0 / self.host_rate_hz
        for seg in self.segments:
            data = seg.command()
            n = max(1, round(seg.duration / period))
            if data is not None:
                out += [(t0 + k * period, data) for k in range(n)]
            t0 += seg.duration
        out.append((t0, velocity_command(0.0, 0.0)))
        return out


def bundled() -> list[Path]:
    """The bundled scenario files, sorted by name."""
    return sorted(BUNDLED.glob("*.toml"))


def find(name_or_path: str) -> Path:
    """The file of a ``.toml`` path or of a bundled scenario's name (ScenarioError when
    there is none)."""
    path = Path(name_or_path)
    if path.suffix == ".toml" and path.exists():
        return path
    candidate = BUNDLED / f"{name_or_path}.toml"
    if candidate.exists():
        return candidate
    names = ", ".join(p.stem for p in bundled())
    raise ScenarioError(f"no scenario {name_or_path!r}: give a .toml path or one of: {names}")


def load(name_or_path: str, *, extra: Collection[str] = ()) -> Scenario:
    """Reads and checks a scenario, by bundled name or path; a ScenarioError names
    what is wrong. ``extra``: top-level keys the caller reads itself (Eddie's ``wall``
    and ``eddie``), accepted here and left alone."""
    path = find(name_or_path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from exc
    _known_keys(data, (*TOP_KEYS, *extra), f"{path}", "at the top level")
    segments = []
    waypoints, follow = _path(data, path)
    for i, raw in enumerate(data.get("segment", [])):
        if not isinstance(raw, dict):
            raise ScenarioError(f"{path}: segments are [[segment]] tables")
        _known_keys(raw, (*_KINDS, "duration"), f"{path}: segment {i + 1}", "")
        kinds = [k for k in _KINDS if k in raw]
        if len(kinds) != 1:
            raise ScenarioError(f"{path}: segment {i + 1} needs exactly one of {', '.join(_KINDS)}")
        kind = kinds[0]
        duration = raw.get("duration")
        if not isinstance(duration, (int, float)) or duration <= 0:
            raise ScenarioError(f"{path}: segment {i + 1} needs a positive duration (s)")
        value = raw[kind]
        values: tuple[float, ...] = () if isinstance(value, bool) else tuple(float(v) for v in value)
        expected = {"cmdvel": 2, "wheel": 2, "ppm": 8, "stop": 0, "silence": 0}[kind]
        if len(values) != expected:
            raise ScenarioError(f"{path}: segment {i + 1}: {kind} takes {expected} values")
        seg = Segment(kind, values, float(duration))
        try:
            seg.command()
        except ValueError as exc:
            raise ScenarioError(f"{path}: segment {i + 1}: {exc}") from exc
        segments.append(seg)
    if not segments and waypoints is None:
        raise ScenarioError(f"{path}: no [[segment]] entries (or a path)")
    if segments and waypoints is not None:
        raise ScenarioError(f"{path}: a scenario has [[segment]] entries or a path, not both")
    repeat = int(data.get("repeat", 1))
    if repeat < 1:
        raise ScenarioError(f"{path}: repeat must be >= 1")
    chair = dict(data.get("chair", {}))
    known = {f.name for f in dataclasses.fields(ChairParams)}
    unknown = set(chair) - known
    if unknown:
        raise ScenarioError(f"{path}: unknown [chair] keys: {', '.join(sorted(unknown))}")
    rate = float(data.get("host_rate_hz", 10.0))
    if not 0.5 <= rate <= 100.0:
        raise ScenarioError(f"{path}: host_rate_hz must be within 0.5..100")
    neutral_first = data.get("neutral_first", True)
    if not isinstance(neutral_first, bool):
        raise ScenarioError(f"{path}: neutral_first must be true or false")
    offset = data.get("host_offset_s", 0.0)
    if isinstance(offset, bool) or not isinstance(offset, (int, float)) or not 0.0 <= offset < 1.0:
        raise ScenarioError(f"{path}: host_offset_s must be a number of seconds in [0, 1), not {offset!r}")
    terrain, world, start = _world(data.get("world", {}), path)
    lidar = _lidar(data.get("lidar"), path)
    expect = None
    if "expect" in data:
        try:
            expect = parse_expect(data["expect"])
        except ValueError as exc:
            raise ScenarioError(f"{path}: [expect] {exc}") from exc
    scenario = Scenario(
        name=str(data.get("name", path.stem)), description=str(data.get("description", "")),
        segments=tuple(segments) * repeat, host_rate_hz=rate,
        settle_s=float(data.get("settle_s", 1.5)), neutral_first=neutral_first,
        host_offset_s=float(offset), chair=chair, source=path,
        path=waypoints, follow=follow, terrain=terrain, world=world, start=start, lidar=lidar,
        expect=expect,
    )
    if world is not None:
        try:
            Plant(scenario.params(), x=start[0], y=start[1], heading=start[2], world=world, use_kernel=False)
        except ValueError as exc:
            raise ScenarioError(f"{path}: [world] start: {exc}") from exc
    board_params = dict(data.get("params", {}))
    for name, value in board_params.items():
        try:
            encode_set(name, value)
        except (ValueError, TypeError) as exc:
            raise ScenarioError(f"{path}: [params] {name}: {exc}") from exc
    raw_faults = data.get("fault", [])
    if not isinstance(raw_faults, list):
        raise ScenarioError(f"{path}: faults are [[fault]] tables")
    faults = tuple(parse_fault(raw, f"{path}: fault {i + 1}", scenario.duration)
                   for i, raw in enumerate(raw_faults))
    try:
        inhibits = parse_inputs(data.get("input"), str(path), scenario.duration)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from exc
    return dataclasses.replace(scenario, faults=faults, inhibits=inhibits,
                               board_params={k: float(v) for k, v in board_params.items()})


def _known_keys(table: dict, known: Collection[str], where: str, what: str) -> None:
    """ScenarioError naming ``table``'s keys that are not ``known``."""
    unknown = set(table) - set(known)
    if unknown:
        place = f" {what}" if what else ""
        raise ScenarioError(f"{where}: unknown keys{place}: {', '.join(sorted(unknown))} "
                            f"(known: {', '.join(known)})")


def _world(raw: object, where: Path) -> tuple[Terrain, World | None, tuple[float, float, float]]:
    """The ``[world]`` table (module docstring): the floor, the walls (None without any)
    and the start pose (x, y, heading in rad)."""
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: world is a table ([world])")
    _known_keys(raw, _WORLD_KEYS, f"{where}: [world]", "")
    return _terrain(raw, where), _walls(raw, where), _start(raw, where)


def _walls(raw: dict, where: Path) -> World | None:
    """The ``[world]`` table's walls (``World.from_table``; a map relative to the
    scenario's file); None when it gives none."""
    table = {k: raw[k] for k in _GEOMETRY_KEYS if k in raw}
    if "file" in raw:
        table = _merge(table, _world_file(raw["file"], where), where)
    if not table:
        return None
    for key in ("walls", "boxes", "circles"):
        entries = table.get(key, [])
        if not isinstance(entries, list) or not all(isinstance(e, list) for e in entries):
            raise ScenarioError(f"{where}: [world] {key} is a list of lists of numbers")
        for i, entry in enumerate(entries):
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                       for v in entry):
                raise ScenarioError(f"{where}: [world] {key}[{i}] must be finite numbers, not {entry}")
    if "map" in table and not isinstance(table["map"], str):
        raise ScenarioError(f"{where}: [world] map is the path of a map_server YAML")
    try:
        world = World.from_table(table, where.parent)
    except (WorldError, MapFileError) as exc:
        raise ScenarioError(f"{where}: [world] {exc}") from exc
    except OSError as exc:
        raise ScenarioError(f"{where}: [world] map: {exc}") from exc
    return world if len(world.segments) or len(world.circles) else None


def _world_file(name: object, where: Path) -> dict:
    """The geometry keys of a hand-written world's own TOML file (``[world] file``), its
    ``map`` made relative to the scenario's file."""
    if not isinstance(name, str):
        raise ScenarioError(f"{where}: [world] file is the path of a world's TOML file")
    path = where.parent / name
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise ScenarioError(f"{where}: [world] file: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where}: [world] file {name}: not valid TOML: {exc}") from exc
    _known_keys(data, (*_GEOMETRY_KEYS, "name", "description"), f"{where}: [world] file {name}", "")
    table = {k: data[k] for k in _GEOMETRY_KEYS if k in data}
    if "map" in table:
        if not isinstance(table["map"], str):
            raise ScenarioError(f"{where}: [world] file {name}: map is the path of a map_server YAML")
        table["map"] = str(Path(name).parent / table["map"])
    return table


def _merge(table: dict, more: dict, where: Path) -> dict:
    """Two sets of geometry keys as one (lists joined; one ``map`` at most)."""
    out = dict(table)
    for key, value in more.items():
        if key == "map":
            if "map" in out:
                raise ScenarioError(f"{where}: [world] has a map and its file another: one map at most")
            out["map"] = value
        else:
            out[key] = [*out.get(key, []), *value]
    return out


def _lidar(raw: object, where: Path) -> Lidar | None:
    """The ``[lidar]`` table (module docstring) as a ``Lidar``; None without one."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: lidar is a table ([lidar])")
    _known_keys(raw, _LIDAR_KEYS, f"{where}: [lidar]", "")
    model = raw.get("model")
    if model not in MODELS:
        raise ScenarioError(f"{where}: [lidar] model must be one of {', '.join(MODELS)}, not {model!r}")
    values = {}
    for key in ("x", "y", "z", "yaw_deg", "roll_deg"):
        value = raw.get(key, getattr(SEED_MOUNT, key, 0.0))
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ScenarioError(f"{where}: [lidar] {key} must be a finite number, not {value!r}")
        values[key] = float(value)
    roll = values.pop("roll_deg") % 360.0
    if roll not in (0.0, 180.0):
        raise ScenarioError(f"{where}: [lidar] roll_deg is 0 (head up) or 180 (head down), not {roll:g}")
    told = raw.get("driver_inverted", False)
    if not isinstance(told, bool):
        raise ScenarioError(f"{where}: [lidar] driver_inverted is true or false, not {told!r}")
    return Lidar(MODELS[model], LidarMount(inverted=roll == 180.0, driver_inverted=told, **values))


def _start(raw: dict, where: Path) -> tuple[float, float, float]:
    """The ``[world]`` table's ``start`` as x, y (m) and heading (rad)."""
    start = raw.get("start", [0.0, 0.0, 0.0])
    if (not isinstance(start, list) or len(start) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                       for v in start)):
        raise ScenarioError(f"{where}: [world] start is [x, y, heading_deg] (finite numbers), not {start!r}")
    return float(start[0]), float(start[1]), math.radians(float(start[2]))


def _terrain(raw: dict, where: Path) -> Terrain:
    """The ``[world]`` table's floor as a ``Terrain``."""
    raw_ramps = raw.get("ramp", [])
    if not isinstance(raw_ramps, list) or not all(isinstance(r, dict) for r in raw_ramps):
        raise ScenarioError(f"{where}: [world] ramps are [[world.ramp]] tables")
    ramps = []
    for i, ramp in enumerate(raw_ramps):
        _known_keys(ramp, _RAMP_KEYS, f"{where}: world.ramp {i + 1}", "")
        missing = [k for k in _RAMP_KEYS if k not in ramp]
        if missing:
            raise ScenarioError(f"{where}: world.ramp {i + 1} needs {', '.join(missing)}")
        try:
            ramps.append(Ramp(ramp["from_x"], ramp["to_x"], ramp["slope_deg"]))
        except ValueError as exc:
            raise ScenarioError(f"{where}: world.ramp {i + 1}: {exc}") from exc
    try:
        return Terrain(raw.get("slope_deg", 0.0), raw.get("downhill_heading_deg", 0.0), tuple(ramps))
    except ValueError as exc:
        raise ScenarioError(f"{where}: [world]: {exc}") from exc


def _path(data: dict, where: Path) -> tuple[tuple[tuple[float, float], ...] | None, FollowParams]:
    """A closed-loop scenario's ``path`` and ``[follow]`` table (module docstring)."""
    raw_follow = data.get("follow", {})
    if "path" not in data:
        if raw_follow:
            raise ScenarioError(f"{where}: [follow] without a path")
        return None, FollowParams()
    raw = data["path"]
    try:
        points = tuple((float(p[0]), float(p[1])) for p in raw)
        if not points or any(len(p) != 2 for p in raw):
            raise ValueError
    except (TypeError, ValueError, IndexError):
        raise ScenarioError(f"{where}: path is a list of [x, y] points (m)") from None
    if data.get("fault"):
        raise ScenarioError(f"{where}: a closed-loop scenario takes no [[fault]]")
    known = {f.name for f in dataclasses.fields(FollowParams)}
    unknown = set(raw_follow) - known
    if unknown:
        raise ScenarioError(f"{where}: unknown [follow] keys: {', '.join(sorted(unknown))} "
                            f"(known: {', '.join(sorted(known))})")
    try:
        follow = FollowParams(**raw_follow)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{where}: [follow]: {exc}") from exc
    return points, follow


def parse_fault(raw: object, where: str, duration: float | None = None) -> Fault:
    """One ``[[fault]]`` table as a ``Fault``; ``where`` starts every ScenarioError's
    message, and ``duration`` (the scenario's, s) bounds ``at``."""
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: a fault is a table ([[fault]])")
    unknown = set(raw) - set(_FAULT_KEYS)
    if unknown:
        raise ScenarioError(f"{where}: unknown keys {', '.join(sorted(unknown))} "
                            f"(a fault takes {', '.join(_FAULT_KEYS)})")
    kind = raw.get("kind")
    if kind not in FAULT_KINDS:
        raise ScenarioError(f"{where}: kind must be one of {', '.join(FAULT_KINDS)}, not {kind!r}")
    at = raw.get("at")
    if isinstance(at, bool) or not isinstance(at, (int, float)):
        raise ScenarioError(f"{where}: at (s from the start) is missing or not a number")
    if kind in SIDED_KINDS and "side" not in raw:
        raise ScenarioError(f"{where}: {kind} needs side = \"left\", \"right\" or \"both\"")
    values: dict[str, object] = {}
    for key in ("duration", "rate_hz"):
        if key in raw:
            value = raw[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ScenarioError(f"{where}: {key} must be a number, not {value!r}")
            values[key] = float(value)
    try:
        fault = Fault(kind=kind, at=float(at), side=raw.get("side"),
                      duration=values.get("duration"), rate_hz=values.get("rate_hz"))  # type: ignore[arg-type]
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from exc
    if duration is not None and fault.at >= duration:
        raise ScenarioError(f"{where}: at = {fault.at} s is not within the scenario "
                            f"({duration:.3f} s)")
    return fault
