"""A fault on a grade does not leave the chair free to roll, on both backends, watched
from the plant.

A wheel whose encoder faults is no longer trusted; the other still is. The healthy
wheel's PID brakes it along the emergency ramp while the faulty motor is at duty 0;
once the healthy wheel is slow the chair parks, the hold keeps the healthy wheel where
it stopped and the faulty one mirrors its duty, open loop (PROTOCOL.md, "Hold and
rollaway"). With a parking brake, the brake engages at the fault.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.support.depth import cases
from tests.support.grade import bundled
from wcdrive.sim import runner, scenario
from wcdrive.sim.result import STANDSTILL_SPEED

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
FAULTS = {"encoder_cut": "EVT:FAULT,ENC_STALL_L", "encoder_reversed": "EVT:FAULT,ENC_REVERSED_L"}


#: Each fault with and without a brake on the port; on simavr (4 to 5 s each) each fault
#: and each brake once at the fast depth, all four at the thorough one.
@pytest.mark.parametrize(("kind", "brake", "backend"), cases(
    [(kind, brake) for kind in sorted(FAULTS) for brake in ("", "_brake")],
    [f"{kind}-{'brake' if brake else 'no-brake'}" for kind in sorted(FAULTS) for brake in ("", "_brake")],
    fast_simavr=["encoder_cut-no-brake", "encoder_reversed-brake"]))
def test_a_fault_down_1_in_12_comes_to_rest_and_stays(kind: str, brake: str, backend: str) -> None:
    """Down 1:12 at 0.5 m/s, the left encoder fails at 1.5 s: the fault latches, the chair
    comes to rest within 4 s and 1.0 m of it and then moves at most 0.03 m over the rest
    of the run (0.005 m with a brake). Both motors at duty 0, as before the healthy wheel
    was kept braking, it never came to rest: 1.8 m down in 3 s, still rolling."""
    r = bundled(f"ramp_fault_{kind}_1in12{brake}", backend)
    faults = [t for t, line in r.link.events if line.startswith("EVT:FAULT")]
    assert [line for _, line in r.link.events if line.startswith("EVT:FAULT")] == [FAULTS[kind]]
    stop = r.stop_metrics()
    assert stop["stop_at_s"] is not None and 0.0 <= faults[0] - stop["stop_at_s"] <= 0.2
    assert stop["rest_at_s"] is not None, stop
    assert stop["stopping_time_s"] is not None and stop["stopping_time_s"] <= 4.0
    assert stop["stopping_distance_m"] is not None and stop["stopping_distance_m"] <= 1.0
    assert stop["drift_parked_m"] is not None and stop["drift_parked_m"] <= (0.005 if brake else 0.03)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_faulty_wheel_is_off_then_mirrors_the_healthy_wheels_hold(backend: str) -> None:
    """From the fault until the chair parks, the faulty (left) motor at duty 0 and the
    healthy one braking (against the downhill roll); parked, both get the same duty in the
    same direction of travel, the hold's, non-zero on the grade."""
    r = bundled("ramp_fault_encoder_cut_1in12", backend)
    fault = next(t for t, line in r.link.events if line.startswith("EVT:FAULT"))
    t = r.board.tick_time
    after = np.flatnonzero(t > fault + 0.06)
    pwm = r.board.pwm[after]
    held = int(np.argmax(pwm[:, 0] != 0))          # the first mirrored duty: parked
    assert held > 0
    assert np.all(pwm[:held, 0] == 0) and np.all(pwm[:held, 1] <= 0) and np.any(pwm[:held, 1] < 0)
    assert np.array_equal(pwm[held:, 0], pwm[held:, 1]) and np.all(pwm[held:] != 0)


LONG = 40.0     # s of the stop after the fault


def test_held_on_one_encoder_the_faulty_side_creeps_and_slows(tmp_path: Path) -> None:
    """The limit of holding on one encoder (port): braked by one wheel the chair turned
    25 degrees before it stopped, and the faulty wheel, mirroring the healthy one's duty
    open loop, creeps uphill as the chair straightens, slowing: 0.04 rad/s at 10 s, under
    0.02 rad/s at 40 s, at most 0.15 m in all (docs/safety.md, "Not safe yet")."""
    text = (Path(scenario.find("ramp_fault_encoder_cut_1in12")).read_text()
            .replace("duration = 3.0", f"duration = {LONG}"))
    path = tmp_path / "long.toml"
    path.write_text(text)
    r = runner.run(scenario.load(str(path)))
    stop = r.stop_metrics()
    assert stop["rest_at_s"] is not None and stop["drift_parked_m"] is not None
    assert stop["drift_parked_m"] <= 0.15
    t = r.board.tick_time
    left = np.abs(r.truth.wheel_speed[:, 0])
    at = [int(np.searchsorted(t, stop["rest_at_s"] + s)) for s in (5.0, LONG - 5.0)]
    assert left[at[1]] < left[at[0]] and left[at[1]] * 0.1524 < STANDSTILL_SPEED
