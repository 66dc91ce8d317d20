"""A scenario's ``[[input]]`` tables: the board's inhibit inputs on a timeline, as the
``[[fault]]`` tables put faults on one (``wcdrive.sim.scenario``'s docstring).

    [[input]]
    at = 3.0                 # s from the start
    input = "charger"        # "charger" (inhibit input 1) or "seat" (input 2), or 1, 2
    active = true            # pulled LOW (true) or released (false; default true)

Each input starts released. Both backends take the timeline: the port as its tick's
input, the compiled firmware in simavr on its pins (``wcdrive.boards.inhibits``).
"""

from __future__ import annotations

from wcdrive.boards.inhibits import InhibitChange, input_number

__all__ = ["parse_inputs"]

_KEYS = ("at", "input", "active")


def parse_inputs(raw: object, where: str, duration: float) -> tuple[InhibitChange, ...]:
    """The ``[[input]]`` tables of a scenario (``raw``, as loaded) as a timeline;
    ``ValueError`` naming ``where`` and the table for anything malformed."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise ValueError(f"{where}: inputs are [[input]] tables")
    changes = []
    for i, table in enumerate(raw):
        here = f"{where}: input {i + 1}"
        if not isinstance(table, dict):
            raise ValueError(f"{here}: an input is a table ([[input]])")
        unknown = set(table) - set(_KEYS)
        if unknown:
            raise ValueError(f"{here}: unknown keys {', '.join(sorted(unknown))} "
                             f"(an input takes {', '.join(_KEYS)})")
        at = table.get("at")
        if isinstance(at, bool) or not isinstance(at, (int, float)) or not 0 <= at < duration:
            raise ValueError(f"{here}: at must be a time within the scenario (0 to {duration:.3f} s), "
                             f"not {at!r}")
        active = table.get("active", True)
        if not isinstance(active, bool):
            raise ValueError(f"{here}: active must be true or false, not {active!r}")
        try:
            number = input_number(table.get("input"))   # type: ignore[arg-type]
        except ValueError as exc:
            raise ValueError(f"{here}: {exc}") from exc
        changes.append(InhibitChange(float(at), number, active))
    return tuple(sorted(changes, key=lambda c: c.at))
