"""Into a wall at any speed the chair drives, not only ``room_wall_bump``'s 0.5 m/s: the
envelope of the stall rule's "a wheel stalled against a wall is no failed encoder"
(docs/safety.md, "Stall timeout"). On the port, the plant and the room of
``room_wall_bump``, the chair 0.5 m short of the east wall, the host asking on for
2.5 s after the impact."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.support.grade import alarms
from wcdrive.firmware import constants as C
from wcdrive.sim import runner, scenario

#: m/s: a crawl to past the top of the indoor profile. Below about 0.125 m/s the chair
#: halts with ``STALLED_ON_GRADE`` about 0.5 s after the impact: the PID's duty, whose
#: error is small, climbs a unit a tick toward the held duty (42), and before it gets
#: there both wheels show effort without progress, the grade rule's "beyond the chair"
#: (docs/safety.md, "Stall timeout"). Safe (the chair stops), but a limit event on the
#: flat, and motion waits for neutral: known, not fixed.
CRAWL = "known: below about 0.125 m/s a wall is STALLED_ON_GRADE before the wheels are held"
#: The fast depth drives at 0.1, 0.15, 0.4 and 0.8 m/s; the thorough one at all of them.
SPEEDS = [pytest.param(0.05, marks=[pytest.mark.xfail(strict=True, reason=CRAWL), pytest.mark.thorough]),
          pytest.param(0.1, marks=pytest.mark.xfail(strict=True, reason=CRAWL)),
          0.15, pytest.param(0.2, marks=pytest.mark.thorough), pytest.param(0.3, marks=pytest.mark.thorough),
          0.4, pytest.param(0.6, marks=pytest.mark.thorough), 0.8]

_ROOM = """
name = "wall_at_{speed}"
description = "Into the east wall at {speed} m/s from 0.5 m short of it, the host asking on."
host_rate_hz = 10

[world]
walls = [[0, 0, 5, 0, 5, 4, 0, 4, 0, 0]]
start = [3.8, 1.5, 0]

[[segment]]
cmdvel = [{speed}, 0.0]
duration = {duration}
"""


@pytest.mark.parametrize("speed", SPEEDS)
def test_into_a_wall_at_any_speed_no_fault_and_both_wheels_held(tmp_path: Path, speed: float) -> None:
    """One collision, no alarm (no encoder, motor or driver fault, no grade limit: the
    wheels stand because the wall holds them), and from 1 s after the impact both
    motors pushing at the held duty, 42 (the motor's full torque at a standstill), each
    encoder creeping STALL_CREEP_COUNTS a tick at most (the tyres give)."""
    path = tmp_path / f"wall_{speed}.toml"
    asking = round(0.5 / speed + 4.0, 2)                      # the host's segment, s
    path.write_text(_ROOM.format(speed=speed, duration=asking))
    r = runner.run(scenario.load(str(path)), backend="port")
    assert r.world is not None and r.world.collisions >= 1
    first = r.world.first_collision_s
    assert first is not None
    assert alarms(r) == []
    t = r.board.tick_time
    pushing = (t > first + 1.0) & (t < asking)             # the host still asking
    assert pushing.sum() >= 20
    assert np.all(np.abs(r.board.pwm[pushing]) == 42), np.unique(r.board.pwm[pushing])
    assert np.all(np.abs(np.diff(r.board.counts[pushing], axis=0)) <= C.STALL_CREEP_COUNTS)
