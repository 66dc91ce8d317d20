"""The plant on a grade against the physics worked out by hand: free rolling, back-EMF
creep, a ramp band's edges, the normal loads, the rated grade. Each test's docstring
holds its derivation; both backends (the C kernel and the Python reference) are run.

Symbols (``ChairParams`` defaults): m = chair + occupant (190 kg), g = 9.81, r the wheel
radius, j the wheel's inertia with the rotor reflected (``wheel_total_inertia``), b the
gear's viscous friction at the wheel, crr and crr_c the drive wheels' and casters'
rolling resistance, a = ``cog_ahead_of_axle``, L = ``caster_ahead_of_axle``, h =
``cog_height``; M = m + 2 j / r^2 the chair's mass with its wheels' and rotors'
inertia seen at the rim.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.params import G
from wcdrive.plant.terrain import Ramp, Terrain

P = ChairParams()
M_EFF = P.mass + 2.0 * P.wheel_total_inertia / P.wheel_radius**2
BACKENDS = pytest.mark.parametrize("use_kernel", [True, False], ids=["kernel", "python"])


def _loads_by_hand(slope: float, facing_downhill: bool) -> tuple[float, float]:
    """(each drive wheel, each caster), N: moments about the drive wheels' contact line."""
    normal = P.mass * G * math.cos(slope)
    tip = P.mass * G * math.sin(slope) * P.cog_height * (1.0 if facing_downhill else -1.0)
    casters = (normal * P.cog_ahead_of_axle + tip) / P.caster_ahead_of_axle
    return (normal - casters) / 2.0, casters / 2.0


def _rolling(slope: float, facing_downhill: bool = True) -> float:
    """N: both drive wheels' and both casters' rolling resistance on that grade."""
    drive, caster = _loads_by_hand(slope, facing_downhill)
    return 2.0 * P.rolling_resistance * drive + 2.0 * P.caster_rolling_resistance * caster


@BACKENDS
def test_unpowered_chair_rolls_down_at_g_sin_less_rolling_resistance(use_kernel: bool) -> None:
    """Both motors dead (open circuit), the chair at rest facing straight down a uniform
    4 degree grade, let go: its speed after 2 s.

    The chassis: ``m dv/dt = m g sin t + 2 F - R``, F the tyre's force on it per wheel
    and R the rolling resistance of all four loads (``_rolling``). A dead motor's wheel:
    ``j dw/dt = -r F - b w``; rolling, ``v = r w``, so ``F = -(j/r^2) dv/dt - (b/r^2) v``
    and::

        M dv/dt = m g sin t - R - (2 b / r^2) v,   M = m + 2 j / r^2
        v(t) = (A / B) (1 - exp(-B t)),   A = (m g sin t - R) / M,   B = 2 b / (r^2 M)

    With these figures A = 0.457 m/s^2 and v(2 s) = 0.907 m/s (the rolling resistance
    takes 37 N of the 130 N pull, the viscous term 1% of the speed). Tolerance 0.5% of
    v; the plant comes out 0.25% faster, as its rolling resistance fades below 1 cm/s
    (tanh(v / 1 cm/s)), the first 50 ms or so.
    """
    t = math.radians(4.0)
    plant = Plant(terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    plant.set_motor_dead("left")
    plant.set_motor_dead("right")
    plant.advance(2000)
    a = (P.mass * G * math.sin(t) - _rolling(t)) / M_EFF
    b = 2.0 * P.viscous_friction / (P.wheel_radius**2 * M_EFF)
    expected = a / b * (1.0 - math.exp(-b * 2.0))
    assert expected == pytest.approx(0.907, abs=0.001)
    assert plant.axle_velocity()[0] == pytest.approx(expected, rel=0.005)


@BACKENDS
def test_shorted_motors_creep_down_at_the_back_emf_terminal_speed(use_kernel: bool) -> None:
    """Duty 0 (``set_drive(0, 1, 0, 1)``: 0 V across each motor, the driver shorting it,
    so its back-EMF drives a braking current), facing straight down a 4 degree grade:
    the speed after 5 s.

    A motor at 0 V carries ``i = -Ke G w / R_a`` and brakes its wheel with ``Ke G eff i``:
    ``-k2 w``, ``k2 = G^2 eff Ke^2 / R_a`` (the plant's ``k2``, 4.92 N m s/rad here),
    below the current limit as long as ``Ke G w < I_max R_a``. Steady, each wheel's
    torques balance, ``r F = -(k2 + b) w``, and the chassis's forces::

        m g sin t - R - 2 (k2 + b) v / r^2 = 0   ->   v = r^2 (m g sin t - R) / (2 (k2 + b))

    0.218 m/s with these figures, reached with a time constant M r^2 / (2 (k2 + b)) =
    0.48 s (so 5 s is 10 of them). The load transfer (``cog_height``) puts 129 N onto the
    casters, whose rolling resistance is twice the drive wheels': 1.9 N more drag, 2% of
    the speed, which the 0.1% tolerance sees. The tyres carry the 46 N of braking each
    with their patches' deflection, not by slipping (``tyre_contact_stiffness``), so the
    plant's speed is the hand figure's to 0.01%; slipping at ``F / tyre_stiffness``
    (0.46 mm/s), it would be 0.2% faster.
    """
    t = math.radians(4.0)
    plant = Plant(terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    plant.set_drive(0, 1, 0, 1)
    plant.advance(5000)
    ke = P.motor_constant
    k2 = P.gear_ratio**2 * P.gear_efficiency * ke**2 / P.armature_resistance
    pull = P.mass * G * math.sin(t) - _rolling(t)
    expected = P.wheel_radius**2 * pull / (2.0 * (k2 + P.viscous_friction))
    assert expected == pytest.approx(0.218, abs=0.001)
    assert ke * P.gear_ratio * expected / P.wheel_radius < P.current_limit * P.armature_resistance
    assert plant.axle_velocity()[0] == pytest.approx(expected, rel=0.001)
    assert abs(plant.left.current) < P.current_limit


@BACKENDS
def test_a_ramp_band_pulls_from_its_edge_to_its_edge(use_kernel: bool) -> None:
    """A band falling at 5 degrees from 1 m to 2 m along +x, level floor either side; the
    chair, motors dead, facing +x at x = 0.7 m, pushed at 0.6 m/s: it rolls onto the band,
    down it and off it. Its acceleration over 30 ms windows just before each edge and
    just after.

    The first test's equation with the grade t where the axle is::

        dv/dt = (m g sin t - R(t)) / M - (2 b / r^2) v / M

    On the level (t = 0) it is all drag: -0.17 m/s^2 here; on the band +0.62 m/s^2. So
    the acceleration jumps by ``m g sin(5 deg) / M`` (less the band's extra rolling
    drag) within the step the axle crosses an edge, and back at the far edge. Tolerance
    0.01 m/s^2 (the windows' own change in v).
    """
    band = math.radians(5.0)
    plant = Plant(terrain=Terrain(0.0, 0.0, (Ramp(1.0, 2.0, 5.0),)), x=0.7, use_kernel=use_kernel)
    plant.set_motor_dead("left")
    plant.set_motor_dead("right")
    v0 = 0.6
    plant.body.velocity = (v0, 0.0)
    plant.s.speed[0] = plant.s.speed[1] = v0 / P.wheel_radius
    xs, vs = [], []
    for _ in range(4000):
        plant.step()
        xs.append(plant.pose[0])
        vs.append(plant.axle_velocity()[0])
    x, v = np.array(xs), np.array(vs)
    assert x[-1] > 2.3                                      # off the band's far edge

    def accel(edge: float, after: bool) -> tuple[float, float]:
        """(measured, expected) m/s^2 over the 30 steps before or after the axle crosses ``edge``."""
        k = int(np.argmax(x >= edge))
        lo, hi = (k + 1, k + 31) if after else (k - 31, k - 1)
        on_band = (edge == 1.0) == after
        t = band if on_band else 0.0
        mean_v = float(np.mean(v[lo:hi]))
        pull = P.mass * G * math.sin(t) - _rolling(t) - 2.0 * P.viscous_friction * mean_v / P.wheel_radius**2
        return (v[hi] - v[lo]) / ((hi - lo) * 0.001), pull / M_EFF

    for edge in (1.0, 2.0):
        for after in (False, True):
            measured, expected = accel(edge, after)
            assert measured == pytest.approx(expected, abs=0.01), (edge, after)
    assert accel(1.0, False)[1] == pytest.approx(-0.17, abs=0.01)
    assert accel(1.0, True)[1] == pytest.approx(0.62, abs=0.01)


@BACKENDS
def test_facing_uphill_the_grade_moves_load_from_the_casters_to_the_drive_wheels(use_kernel: bool) -> None:
    """The chair facing straight up an 8 degree grade: the normal loads.

    Moments about the drive wheels' contact line, in the chair's pitch plane: the floor
    carries ``m g cos t`` at a = 0.12 m ahead; the grade's pull ``m g sin t`` acts along the
    floor at h = 0.45 m above it, pitching the chair back (facing uphill). The casters,
    at L = 0.45 m::

        2 N_caster = m g (a cos t - h sin t) / L
        2 N_drive  = m g cos t - 2 N_caster

    So each caster loses ``m g sin t h / (2 L)`` = 129.7 N of its share of ``m g cos t``
    and each drive wheel gains it: 806.5 N and 116.4 N here, against 683.4 N and 248.5 N
    on the flat. Tolerance 1e-9 relative (the same arithmetic); then the
    drive tyres' grip is ``mu N_drive``: on a slippery 0.05 floor, full duty spins them
    and each pushes with exactly that.
    """
    t = math.radians(8.0)
    plant = Plant(terrain=Terrain(8.0, 0.0), heading=math.pi, use_kernel=use_kernel)
    drive, caster = _loads_by_hand(t, facing_downhill=False)
    assert (drive, caster) == pytest.approx((806.5, 116.4), abs=0.1)
    assert Plant(use_kernel=use_kernel).normal_loads == pytest.approx((683.4, 248.5), abs=0.1)
    assert plant.normal_loads == pytest.approx((drive, caster), rel=1e-9)
    assert P.grade_loads(t, math.pi) == pytest.approx((drive, caster), rel=1e-9)
    plant.set_drive(0, 1, 0, 1)
    plant.advance(200)                                       # the loads as the plant steps
    assert plant.normal_loads == pytest.approx((drive, caster), rel=1e-6)

    slippery = ChairParams(friction=0.05)
    uphill = Plant(slippery, terrain=Terrain(3.0, 0.0), heading=math.pi, use_kernel=use_kernel)
    uphill.set_drive(255, 1, 255, 1)
    uphill.advance(200)
    drive_3 = _loads_by_hand(math.radians(3.0), facing_downhill=False)[0]
    assert uphill.left.slip > 0.01                          # spinning
    assert uphill.left.force == pytest.approx(0.05 * drive_3, rel=1e-9)


@BACKENDS
def test_the_rated_grade_is_the_steepest_the_motors_climb_from_rest(use_kernel: bool) -> None:
    """``ChairParams.rated_grade``: full duty, facing uphill, from rest, 4 s. Half a degree
    below the rated grade the chair climbs (faster than 5 cm/s by then); half a degree
    above it it stalls (slower than 1 cm/s: the plant's rolling resistance fades below
    1 cm/s, tanh(v / 1 cm/s), so a stalled chair creeps rather than stands).

    At stall both motors sit at the driver's current limit, ``2 G eff Ke I / r`` =
    191 N at the rim; climbing, the grade's pull and the rolling resistance of the
    uphill-facing loads (``grade_loads``) oppose it: 4.87 degrees for 190 kg."""
    rated = P.rated_grade()
    assert rated == pytest.approx(4.87, abs=0.01)
    for grade, climbs in ((rated - 0.5, True), (rated + 0.5, False)):
        plant = Plant(terrain=Terrain(grade, 0.0), heading=math.pi, use_kernel=use_kernel)
        plant.set_drive(255, 1, 255, 1)
        plant.advance(4000)
        speed = plant.axle_velocity()[0]                     # forward: uphill
        assert (speed > 0.05 if climbs else abs(speed) < 0.01), (grade, speed)


@BACKENDS
def test_the_hold_grade_is_the_steepest_the_motors_brake_the_chair_on(use_kernel: bool) -> None:
    """``ChairParams.hold_grade``: both duties 0 (the driver shorts the motors: above
    0.44 m/s their back-EMF drives the current limit), nose downhill, from rest. Half a
    degree below the hold grade the chair settles at its terminal speed (within 1 cm/s
    over the fourth second); half a degree above it it keeps gaining, at about
    g (sin(t) - sin(hold)) = 0.08 m/s^2. Going down, rolling resistance helps the
    brakes: 7.08 degrees against the 4.87 climbed; one motor alone, 4.09."""
    hold = P.hold_grade()
    assert hold == pytest.approx(7.08, abs=0.01)
    assert P.hold_grade(motors=1) == pytest.approx(4.09, abs=0.01)
    assert P.hold_grade(motors=1) < math.degrees(math.atan(1 / 12)) < P.rated_grade() < hold
    for grade, held in ((hold - 0.5, True), (hold + 0.5, False)):
        plant = Plant(terrain=Terrain(grade, 0.0), heading=0.0, use_kernel=use_kernel)
        plant.set_drive(0, 1, 0, 1)
        plant.advance(3000)
        before = plant.axle_velocity()[0]
        plant.advance(1000)
        gain = plant.axle_velocity()[0] - before
        assert (abs(gain) < 0.01 if held else gain > 0.04), (grade, gain)


def test_rated_grade_falls_with_the_occupant() -> None:
    """Heavier occupants, shallower rated grades; the default's is its occupant's."""
    grades = [P.rated_grade(m) for m in (40.0, 80.0, 150.0)]
    assert grades[0] > grades[1] > grades[2] > 0.0
    assert grades[1] == P.rated_grade()
