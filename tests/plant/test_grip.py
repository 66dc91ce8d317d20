"""The drive tyres' static grip against the physics worked out by hand: a locked chair on
a grade within the tyres' friction holds at its patches' deflection and does not creep;
beyond it, it slides at the acceleration the friction leaves. Both backends (the C
kernel and the Python reference) are run.

Symbols (``ChairParams`` defaults): m = chair + occupant (190 kg), g = 9.81, k the
patch's longitudinal stiffness (``tyre_contact_stiffness``, 2e5 N/m), c its damping
(``tyre_stiffness``, 1e5 N per m/s), t the grade.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.params import G
from wcdrive.plant.terrain import Terrain

P = ChairParams()
BACKENDS = pytest.mark.parametrize("use_kernel", [True, False], ids=["kernel", "python"])
#: degrees: a 1:12 ramp (the steepest an ADA ramp may be).
ONE_IN_12 = math.degrees(math.atan(1.0 / 12.0))


def _locked_travel(params: ChairParams, slope_deg: float, seconds: float, use_kernel: bool,
                   every: int = 100) -> np.ndarray:
    """m: how far the axle midpoint has moved down the grade, every ``every`` steps over
    ``seconds``, for a chair facing straight down a uniform grade with both drive wheels
    locked, from rest."""
    plant = Plant(params, terrain=Terrain(slope_deg, 0.0), use_kernel=use_kernel)
    plant.set_wheel_locked("left")
    plant.set_wheel_locked("right")
    x0 = plant.pose[0]
    out = []
    for _ in range(round(seconds * 1000) // every):
        plant.advance(every)
        out.append(plant.pose[0] - x0)
    assert plant.left.angle == plant.right.angle == 0.0
    return np.array(out)


@BACKENDS
@pytest.mark.parametrize(("slope_deg", "by_hand_mm"), [(ONE_IN_12, 0.387), (8.0, 0.648)],
                         ids=["1:12", "8deg"])
def test_a_locked_chair_on_a_grade_holds_at_its_tyres_static_deflection(
        use_kernel: bool, slope_deg: float, by_hand_mm: float) -> None:
    """Both drive wheels locked, the chair facing straight down the grade, let go from
    rest: where it is over 60 s.

    Standing still, the casters carry no force along the grade (their rolling
    resistance fades to 0 at rest) and the drive wheels no lateral one, so the two drive
    tyres hold the grade's whole pull, ``m g sin t``, each half of it with its patch's
    deflection::

        x = m g sin t / (2 k)

    77.4 N and 0.387 mm on 1:12 (4.76 degrees), 129.7 N and 0.648 mm on 8 degrees. The
    two patches are a spring 2k and a damper 2c in parallel on the chassis's mass,
    damped far beyond critical (``c / sqrt(2 k m)`` = 11.5): the chair settles onto x
    as ``x (1 - exp(-t k / c))``, the time constant ``c / k`` = 0.5 s, without
    overshoot. So over the 60 s it never moves further than x (to 1e-6, rounding), is at
    63% of it (1 - 1/e, within 2%: the casters' rolling drag on the way) after 0.5 s and
    within 0.1% of it from 5 s on, and does not move over the last 30 s (less than a
    nanometre). Regularised Coulomb friction (the plant before its patches had springs)
    crept 46 mm on 1:12 over the 60 s, 0.77 mm/s, and 77 mm on 8 degrees.
    """
    t = math.radians(slope_deg)
    x = P.mass * G * math.sin(t) / (2.0 * P.tyre_contact_stiffness)
    assert x * 1000.0 == pytest.approx(by_hand_mm, abs=0.001)
    travel = _locked_travel(P, slope_deg, 60.0, use_kernel)      # every 0.1 s
    assert travel.max() <= x * (1.0 + 1e-6)
    assert travel[4] == pytest.approx(x * (1.0 - math.exp(-1.0)), rel=0.02)
    assert travel[49:] == pytest.approx(x, rel=0.001)            # from 5 s on
    assert abs(travel[-1] - travel[299]) < 1e-9                   # the last 30 s


@BACKENDS
def test_a_locked_chair_across_a_grade_holds_sideways_at_its_tyres_static_deflection(
        use_kernel: bool) -> None:
    """Both drive wheels locked, the chair facing across a 1:12 grade (the floor falling
    to its right), let go from rest: where it is after 10 s and 20 s.

    The grade's pull, ``F = m g sin t`` = 154.8 N, acts sideways at the centre of
    gravity, a = 0.12 m ahead of the axle. Sideways the two patches hold it, each with
    its lateral deflection (``lateral_contact_stiffness`` k_y = 1e5 N/m); the lateral
    forces act on the axle line, so its moment about the axle midpoint, ``F a``, is held
    by the patches' longitudinal deflections, ``+-(W / 2) yaw`` on either side (W the
    wheelbase, 0.57 m)::

        lateral = F / (2 k_y) = 0.774 mm
        2 k (W / 2)^2 yaw = F a   ->   yaw = 2 F a / (k W^2) = 0.572 mrad, nose downhill

    Tolerance 1e-4 relative; the chair does not move between 10 s and 20 s (less than a
    nanometre). Regularised Coulomb friction slid it sideways at 3.7 mm/s, turning as it went.
    """
    t = math.atan(1.0 / 12.0)
    pull = P.mass * G * math.sin(t)
    lateral = pull / (2.0 * P.lateral_contact_stiffness)
    yaw = 2.0 * pull * P.cog_ahead_of_axle / (P.tyre_contact_stiffness * P.wheelbase**2)
    assert (lateral * 1e3, yaw * 1e3) == pytest.approx((0.774, 0.572), abs=0.001)
    plant = Plant(heading=math.pi / 2, terrain=Terrain(ONE_IN_12, 0.0), use_kernel=use_kernel)
    plant.set_wheel_locked("left")
    plant.set_wheel_locked("right")
    x0, y0, h0 = plant.pose
    plant.advance(10000)
    x, y, h = plant.pose
    assert (x - x0, h0 - h) == pytest.approx((lateral, yaw), rel=1e-4)   # downhill is +x, to its right
    assert abs(y - y0) < 1e-6
    plant.advance(10000)
    assert plant.pose == pytest.approx((x, y, h), abs=1e-9)


@BACKENDS
def test_a_locked_chair_beyond_its_tyres_grip_slides_at_the_acceleration_friction_leaves(
        use_kernel: bool) -> None:
    """Both drive wheels locked on a floor of friction 0.05, facing straight down an 8
    degree grade: the chassis's acceleration between 0.5 s and 2.5 s.

    tan(8 deg) = 0.14 > 0.05, so the tyres slide, each at ``mu N_drive``. The locked
    wheels do not turn, so no wheel inertia enters; the casters roll, against their
    rolling resistance ``crr_c N_caster``. With the loads facing downhill
    (``ChairParams.grade_loads``: 547.1 N each drive wheel, 375.8 N each caster, the
    grade's pull tipping load onto the casters)::

        m a = m g sin t - 2 mu N_drive - 2 crr_c N_caster

    259.4 - 54.7 - 22.5 N on 190 kg: 0.959 m/s^2 (a block, ``g (sin t - mu cos t)``,
    0.880 m/s^2: here the casters carry 41% of the load and roll). Tolerance 1%.
    """
    slippery = ChairParams(friction=0.05)
    t = math.radians(8.0)
    drive, caster = slippery.grade_loads(t, 0.0)
    assert (drive, caster) == pytest.approx((547.1, 375.8), abs=0.1)
    a = (slippery.mass * G * math.sin(t) - 2.0 * 0.05 * drive
         - 2.0 * slippery.caster_rolling_resistance * caster) / slippery.mass
    assert a == pytest.approx(0.959, abs=0.001)
    plant = Plant(slippery, terrain=Terrain(8.0, 0.0), use_kernel=use_kernel)
    plant.set_wheel_locked("left")
    plant.set_wheel_locked("right")
    plant.advance(500)
    v0 = plant.axle_velocity()[0]
    plant.advance(2000)
    assert (plant.axle_velocity()[0] - v0) / 2.0 == pytest.approx(a, rel=0.01)
    assert plant.left.force == pytest.approx(-0.05 * plant.normal_loads[0], rel=1e-9)   # sliding


@BACKENDS
def test_a_steady_pull_is_held_by_the_patch_without_slip(use_kernel: bool) -> None:
    """Full duty on the flat, 20 s: at the seed's top speed each tyre pushes the chair
    against its rolling resistance with a steady force, which the patch's spring
    carries (``F = k z``, the deflection z) with no slip left (below 1 um/s; regularised
    Coulomb friction slipped ``F / c`` for it, 0.18 mm/s here)."""
    plant = Plant(use_kernel=use_kernel)
    plant.set_drive(255, 1, 255, 1)
    plant.advance(20000)
    assert plant.left.force > 5.0
    assert abs(plant.left.slip) < 1e-6
    assert plant.s.defl[0] * P.tyre_contact_stiffness == pytest.approx(plant.left.force, rel=1e-6)


@BACKENDS
def test_a_wheel_without_grip_spins_up_to_its_motors_no_load_speed(use_kernel: bool) -> None:
    """A drive wheel on ice (friction 0) at full duty: no tyre force, so its equation is
    ``j dw/dt = k1 v - (k2 + b) w`` once the current is off its limit, and it settles at
    ``w = k1 v / (k2 + b)``, the motor's no-load speed through the gear. It must not run
    away on the current limit's torque it had at the start (the limit is solved again
    while the patch slides). The other wheel grips and stands (duty 0)."""
    plant = Plant(dataclasses.replace(P, friction_right=0.0), use_kernel=use_kernel)
    plant.set_drive(0, 1, 255, 1)
    plant.advance(8000)
    s = plant.s
    no_load = s.k1 * s.volts[1] / (s.k2 + s.b)
    assert plant.right.speed == pytest.approx(no_load, rel=1e-3)
    assert abs(plant.right.current) < s.i_max_r / s.res
