"""Helpers for the tests on a grade: the alarm events a healthy chair must never send,
and a scenario run on a backend, held bit for bit to the firmware on simavr."""

from __future__ import annotations

from functools import cache

from wcdrive.sim import runner, scenario
from wcdrive.sim.scenario import Scenario

#: What a healthy chair within its rated grade never sends.
ALARMS = ("EVT:FAULT", "EVT:ROLLAWAY", "EVT:OVERSPEED", "EVT:STALLED_ON_GRADE")


def alarms(r: runner.SimResult) -> list[str]:
    """The run's ``ALARMS`` lines."""
    return [line for _, line in r.link.events if line.startswith(ALARMS)]


def checked_run(sc: Scenario, backend: str) -> runner.SimResult:
    """``runner.run`` on ``backend``; on simavr the lock-step comparison must have run
    and found no port/firmware difference."""
    r = runner.run(sc, backend=backend)
    if backend == "simavr":
        assert r.lockstep is not None and r.firmware_differences == 0
    return r


@cache
def bundled(name: str, backend: str) -> runner.SimResult:
    """``checked_run`` of a bundled scenario, once per name and backend."""
    return checked_run(scenario.load(name), backend)
