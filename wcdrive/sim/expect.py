"""A scenario's ``[expect]`` table: what a run of it must show, in machine terms
(``wcdrive sim NAME --check`` holds a run to it: ``wcdrive.sim.contract``).

    [expect]
    events = ["FAULT,ENC_STALL_L"]   # kinds that must each appear at least once
    allow = ["ROLLAWAY"]             # kinds that may appear, and need not
    safety = true                    # also wcdrive.sim.safety's bounds (docs/safety.md)
    stopping_distance_m = { max = 0.3 }            # a figure within bounds,
    standstill_after_fault_s = { max = "standstill_bound" }   # or a named bound
    collisions = 0                   # a figure equal to a number or true/false
    [[expect.event]]                 # an expected kind with a time window
    kind = "OVERSPEED"
    from = "runaway"                 # start (default) | fault | stop | stall | runaway
    after_s = -0.2                   # the window opens this long after it (default 0)
    within_s = 0.4                   # and stays open this long (default: to the end)
    [[expect.stop]]                  # the stop figures of an earlier stop
    at_s = 4.02                      # s: when it began (a stop command from the host)
    parked_s = 4.5                   # s: the drift window after its rest (default: to the end)
    stopping_distance_m = { max = 0.29 }

**Events.** A kind is an ``EVT:`` line without ``EVT:``; a listed kind matches the line
equal to it or starting with it and a comma (``FAULT`` matches every fault,
``FAULT,MOTOR_L`` one); a kind ending in ``*`` matches every line that starts with the
rest (``FAULT,ENC_STALL_*``: either side); alternatives joined by ``|`` match where any
does (``FAULT,ENC_STALL_*|STALLED_ON_GRADE``: either answer must come). The
informational kinds (``INFORMATIONAL``: the parameter block's ``PARAMS_LOADED`` and
``PARAMS_DEFAULT``, and ``NEUTRAL``, a neutral command confirmed after a refusal) are
ignored; every other kind is an alarm (``FAULT,*``, ``OVERSPEED``, ``ROLLAWAY``,
``STALLED_ON_GRADE``, ``WATCHDOG``, ``ESTOP``, ``PPM_LOST``, ``NOT_NEUTRAL``,
``DEFLECTED``, and any kind not known here), and an alarm line that no kind of ``events``, ``allow``
or ``[[expect.event]]`` matches is a miss. Except a ``WATCHDOG``
that follows another alarm (the board has stopped already and refuses motion, so the
host's commands no longer keep its watchdog fed) or comes after the host's last command
(an open-loop scenario ends with a stop and then says nothing for ``settle_s``; a
closed-loop one once it reached its goal): that is the host leaving, not an alarm.

**Figures.** Every other key of ``[expect]`` names a figure of the run (``FIGURES``:
``SimResult.metrics``'s, ``max_speed_mps`` (the chair's largest speed over the run),
``first_motion_s`` (when the chair first moved faster than 5 cm/s; None: never), and
Eddie's: ``wcdrive.eddie.runner.figures``). ``{ min = .., max = .. }`` bounds it (either
side may be left out), a bare number or true/false must equal it; a figure the run does
not have (None: e.g. a drift where the chair never came to rest) misses every bound.
The named bounds (``NAMED_BOUNDS``) are computed from the scenario and the run
(``wcdrive.sim.contract``). On the simavr backend, ``firmware_differences`` must be 0
whatever the table says; on the port it is not checked.

An unknown key, kind of anchor or named bound is a ``ValueError`` that names it (the
scenario's loader makes it a ScenarioError naming the file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The kinds of ``EVT:`` line that are not alarms.
INFORMATIONAL = ("PARAMS_LOADED", "PARAMS_DEFAULT", "NEUTRAL")
#: What an event's window may count from: the start of the run, the first fault
#: (``fault_at_s``), the last stop (``stop_at_s``), the first stall of the chair while the
#: host still commands motion, the first runaway of both wheels under braking
#: (``wcdrive.sim.contract.anchor``).
ANCHORS = ("start", "fault", "stop", "stall", "runaway")
#: Bounds by name (``wcdrive.sim.contract.named_bound``).
NAMED_BOUNDS = ("standstill_bound", "stopping_bound", "terminal_speed")
_STOP_FIGURES = ("stop_at_s", "max_speed_after_stop_mps", "rest_at_s", "stopping_time_s",
                 "stopping_distance_m", "travel_after_stop_m", "drift_parked_m")
#: The figures a bound may name.
FIGURES = (
    *_STOP_FIGURES,
    "max_tick_gap_ms", "fault_at_s", "pwm_zero_after_fault_s", "standstill_after_fault_s",
    "travel_after_fault_m", "peak_speed_after_fault_mps", "max_speed_mps", "first_motion_s",
    "collisions", "first_collision_s", "max_impact_ns", "contact_s",
    "goal_error_m", "goal_reached_s", "goal_within_tolerance", "firmware_differences",
    "truth_x", "truth_y", "truth_heading_deg", "tracking_rms_rad_s", "ticks", "simulated_s",
    "winding_temp_max_c", "battery_min_v", "distance_m",
    *(f"odom_{o}_{e}" for o in ("wheel", "velocity", "gyro")
      for e in ("position_error_m", "heading_error_deg")),
    # Eddie's (wcdrive.eddie.runner.figures)
    "path_length_m", "final_error_m", "final_heading_error_deg", "max_error_m", "deadman_stops",
    "nearest_ping_m", "nearest_ping_true_m", "ping_error_m",
)
_EVENT_KEYS = ("kind", "from", "after_s", "within_s")
_STOP_KEYS = ("at_s", "parked_s")


@dataclass(frozen=True)
class Bound:
    """A figure's bound: ``low``..``high`` (a number, a ``NAMED_BOUNDS`` name, or None:
    open), or ``equals`` (a number or a bool; then ``low`` and ``high`` are None)."""

    figure: str
    low: float | str | None = None
    high: float | str | None = None
    equals: float | bool | None = None

    def describe(self, low: float | None = None, high: float | None = None) -> str:
        """The bound in words (``low``/``high``: the named bounds' values, if known)."""
        if self.equals is not None:
            return f"= {_fmt(self.equals)}"
        parts = []
        for sign, given, value in ((">=", self.low, low), ("<=", self.high, high)):
            if given is None:
                continue
            if isinstance(given, str):
                parts.append(f"{sign} {given}" + ("" if value is None else f" ({_fmt(value)})"))
            else:
                parts.append(f"{sign} {_fmt(given)}")
        return " and ".join(parts)


@dataclass(frozen=True)
class EventWindow:
    """An ``[[expect.event]]``: a line of ``kind`` at ``from_`` + ``after_s`` or later, and
    no later than ``within_s`` after that (None: to the end)."""

    kind: str
    from_: str = "start"
    after_s: float = 0.0
    within_s: float | None = None


@dataclass(frozen=True)
class StopCheck:
    """An ``[[expect.stop]]``: the stop figures counted from ``at_s`` (the drift over
    ``parked_s`` after the rest; None: to the end), held to ``bounds``."""

    at_s: float
    parked_s: float | None
    bounds: tuple[Bound, ...]


@dataclass(frozen=True)
class Expect:
    """A parsed ``[expect]`` table (module docstring)."""

    events: tuple[str, ...] = ()
    allow: tuple[str, ...] = ()
    windows: tuple[EventWindow, ...] = ()
    bounds: tuple[Bound, ...] = ()
    stops: tuple[StopCheck, ...] = ()
    safety: bool = False

    def listed(self) -> tuple[str, ...]:
        """Every kind the table names: the alarms it allows."""
        return (*self.events, *self.allow, *(w.kind for w in self.windows))


def matches(kind: str, body: str) -> bool:
    """Whether a listed ``kind`` matches an event line's body (``EVT:`` stripped); a
    kind of alternatives joined by ``|`` matches where any of them does."""
    if "|" in kind:
        return any(matches(k.strip(), body) for k in kind.split("|"))
    if kind.endswith("*"):
        return body.startswith(kind[:-1])
    return body == kind or body.startswith(kind + ",")


def is_alarm(body: str) -> bool:
    """Whether an event line's body (``EVT:`` stripped) is an alarm (module docstring)."""
    return not any(matches(k, body) for k in INFORMATIONAL)


def parse(raw: object) -> Expect:
    """The ``[expect]`` table ``raw`` as an ``Expect``; a ValueError names what is wrong."""
    if not isinstance(raw, dict):
        raise ValueError("expect is a table ([expect])")
    events = _kinds(raw, "events")
    allow = _kinds(raw, "allow")
    safety = raw.get("safety", False)
    if not isinstance(safety, bool):
        raise ValueError(f"safety is true or false, not {safety!r}")
    windows = tuple(_window(w, i) for i, w in enumerate(_tables(raw, "event")))
    stops = tuple(_stop(s, i) for i, s in enumerate(_tables(raw, "stop")))
    special = ("events", "allow", "safety", "event", "stop")
    bounds = tuple(_bound(k, v, "") for k, v in raw.items() if k not in special)
    return Expect(events, allow, windows, bounds, stops, safety)


def _kinds(raw: dict, key: str) -> tuple[str, ...]:
    value = raw.get(key, [])
    if not isinstance(value, list) or not all(isinstance(k, str) and k for k in value):
        raise ValueError(f"{key} is a list of event kinds (strings), not {value!r}")
    bad = [k for k in value if k.startswith("EVT:")]
    if bad:
        raise ValueError(f"{key}: give the kind without EVT: ({bad[0]!r})")
    return tuple(value)


def _tables(raw: dict, key: str) -> list[dict]:
    value = raw.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ValueError(f"{key} entries are [[expect.{key}]] tables")
    return value


def _number(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, not {value!r}")
    return float(value)


def _unknown(table: dict, known: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ValueError(f"{where}: unknown keys: {', '.join(unknown)} (known: {', '.join(known)})")


def _window(raw: dict, i: int) -> EventWindow:
    where = f"event {i + 1}"
    _unknown(raw, _EVENT_KEYS, where)
    kind = raw.get("kind")
    if not isinstance(kind, str) or not kind or kind.startswith("EVT:"):
        raise ValueError(f"{where}: kind is an event kind without EVT:, not {kind!r}")
    anchor = raw.get("from", "start")
    if anchor not in ANCHORS:
        raise ValueError(f"{where}: from must be one of {', '.join(ANCHORS)}, not {anchor!r}")
    after = _number(raw.get("after_s", 0.0), f"{where}: after_s")
    within = None if "within_s" not in raw else _number(raw["within_s"], f"{where}: within_s")
    if within is not None and within < 0:
        raise ValueError(f"{where}: within_s must be >= 0")
    return EventWindow(kind, anchor, after, within)


def _stop(raw: dict, i: int) -> StopCheck:
    where = f"stop {i + 1}"
    if "at_s" not in raw:
        raise ValueError(f"{where}: at_s (s: when the stop began) is missing")
    at = _number(raw["at_s"], f"{where}: at_s")
    parked = None if "parked_s" not in raw else _number(raw["parked_s"], f"{where}: parked_s")
    bounds = []
    for key, value in raw.items():
        if key in _STOP_KEYS:
            continue
        if key not in _STOP_FIGURES:
            known = ", ".join((*_STOP_KEYS, *_STOP_FIGURES))
            raise ValueError(f"{where}: unknown keys: {key} (known: {known})")
        bounds.append(_bound(key, value, f"{where}: "))
    return StopCheck(at, parked, tuple(bounds))


def _bound(figure: str, value: object, where: str) -> Bound:
    if figure not in FIGURES:
        raise ValueError(f"{where}unknown keys: {figure} (known: events, allow, safety, event, stop, "
                         f"and the figures {', '.join(FIGURES)})")
    if isinstance(value, bool):
        return Bound(figure, equals=value)
    if isinstance(value, (int, float)):
        return Bound(figure, equals=_number(value, f"{where}{figure}"))
    if not isinstance(value, dict) or not value:
        raise ValueError(f"{where}{figure} is {{ min = .., max = .. }}, a number or true/false, "
                         f"not {value!r}")
    _unknown(value, ("min", "max"), f"{where}{figure}")
    low, high = (_limit(value.get(k), f"{where}{figure}.{k}") for k in ("min", "max"))
    if isinstance(low, float) and isinstance(high, float) and low > high:
        raise ValueError(f"{where}{figure}: min {low:g} is above max {high:g}")
    return Bound(figure, low, high)


def _limit(value: object, what: str) -> float | str | None:
    if value is None:
        return None
    if isinstance(value, str):
        if value not in NAMED_BOUNDS:
            raise ValueError(f"{what}: a number or one of {', '.join(NAMED_BOUNDS)}, not {value!r}")
        return value
    return _number(value, what)


def _fmt(value: object) -> str:
    if isinstance(value, bool) or value is None:
        return str(value).lower() if isinstance(value, bool) else "none"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
