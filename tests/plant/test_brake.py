"""The parking brake (``ChairParams.parking_brake``, ``Plant.set_brake``) against the
physics worked out by hand: it holds a heavy chair on 1:8, lets it roll when released,
engages after its delay and stops the chair in the distance its torque gives, slips
when too weak for the grade, sums with the shorted motors' braking, and is not there
on a chair without one. Both backends (the C kernel and the Python reference) are run,
and held to each other.

Symbols (``ChairParams`` defaults): m the chair's and occupant's mass, g = 9.81, r the
wheel radius (0.1524 m), j the wheel's inertia with the rotor reflected
(``wheel_total_inertia``), b the gear's viscous friction at the wheel, T the brake's
torque per wheel (``brake_torque``, 50 N m), k the tyre patch's stiffness
(``tyre_contact_stiffness``); M = m + 2 j / r^2 the chair's mass with its wheels' and
rotors' inertia seen at the rim; R the rolling resistance of all four loads.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.params import G
from wcdrive.plant.terrain import Terrain

BACKENDS = pytest.mark.parametrize("use_kernel", [True, False], ids=["kernel", "python"])
BRAKED = ChairParams(parking_brake=True)
#: The heaviest chair: 110 kg with a 150 kg occupant.
HEAVY = ChairParams(parking_brake=True, occupant_mass=150.0)
#: degrees: a 1:8 grade.
ONE_IN_8 = math.degrees(math.atan(1.0 / 8.0))


def _m_eff(p: ChairParams) -> float:
    return p.mass + 2.0 * p.wheel_total_inertia / p.wheel_radius**2


def _rolling(p: ChairParams, slope: float) -> float:
    """N: R, facing straight downhill (``ChairParams.grade_loads``)."""
    drive, caster = p.grade_loads(slope, 0.0)
    return 2.0 * p.rolling_resistance * drive + 2.0 * p.caster_rolling_resistance * caster


def _roll_freely(plant: Plant) -> None:
    """Both motors dead (open circuit): no back-EMF braking, the brake alone."""
    plant.set_motor_dead("left")
    plant.set_motor_dead("right")


@BACKENDS
def test_engaged_it_holds_the_heaviest_chair_on_1_in_8(use_kernel: bool) -> None:
    """The heaviest chair (260 kg) facing straight down 1:8 (7.1 degrees), the brake
    engaged as a new plant's is (the pin an input), duty 0: how far it moves in 60 s.

    Holding a wheel still takes ``m g sin t r / 2`` = 24.1 N m, within T = 50 N m, so
    the wheels stay still and the chair moves by the tyres' static deflection only,
    ``m g sin t / (2 k)`` = 0.791 mm, settling within seconds (tests/plant/test_grip.py),
    then not at all: under 1 mm over the 60 s, and less than a nanometre over the last
    30 s. The shorted motors give nothing at rest; the brake holds it all.
    """
    t = math.atan(1.0 / 8.0)
    torque = HEAVY.mass * G * math.sin(t) * HEAVY.wheel_radius / 2.0
    deflection = HEAVY.mass * G * math.sin(t) / (2.0 * HEAVY.tyre_contact_stiffness)
    assert torque == pytest.approx(24.1, abs=0.05)
    assert deflection * 1e3 == pytest.approx(0.791, abs=0.001)
    plant = Plant(HEAVY, terrain=Terrain(ONE_IN_8, 0.0), use_kernel=use_kernel)
    assert plant.brake_engaged
    x0 = plant.pose[0]
    plant.advance(30000)
    x30 = plant.pose[0]
    plant.advance(30000)
    assert plant.pose[0] - x0 < 1e-3
    assert plant.pose[0] - x0 == pytest.approx(deflection, rel=1e-3)
    assert abs(plant.pose[0] - x30) < 1e-9
    assert plant.left.angle == plant.right.angle == 0.0
    assert plant.brake_engaged


@BACKENDS
def test_released_the_chair_rolls_as_one_without_a_brake(use_kernel: bool) -> None:
    """Motors dead, facing straight down 4 degrees, the pin driven high at t = 0: the
    brake holds for its release delay (50 ms), then the chair rolls as one without a
    brake does (tests/plant/test_terrain.py's free roll): 2 s after the release its speed
    is within 0.1% of a brakeless chair's 2 s after it was let go, and of the hand
    figure, ``(A / B) (1 - exp(-B t))`` with ``A = (m g sin t - R) / M`` and
    ``B = 2 b / (r^2 M)``: 0.907 m/s, within 0.5% (the plant's rolling resistance
    fades below 1 cm/s: 0.25% faster)."""
    plant = Plant(BRAKED, terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    _roll_freely(plant)
    plant.set_brake(True)
    plant.advance(49)
    assert plant.brake_engaged and plant.left.angle == 0.0
    plant.advance(1)
    assert not plant.brake_engaged
    plant.advance(2000)
    free = Plant(terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    _roll_freely(free)
    free.advance(2000)
    t = math.radians(4.0)
    m = _m_eff(BRAKED)
    a = (BRAKED.mass * G * math.sin(t) - _rolling(BRAKED, t)) / m
    b = 2.0 * BRAKED.viscous_friction / (BRAKED.wheel_radius**2 * m)
    assert plant.axle_velocity()[0] == pytest.approx(free.axle_velocity()[0], rel=0.001)
    assert plant.axle_velocity()[0] == pytest.approx(a / b * (1.0 - math.exp(-b * 2.0)), rel=0.005)


@BACKENDS
def test_engaged_at_speed_it_acts_after_its_delay_and_stops_the_chair_in_v2_over_2a(
        use_kernel: bool) -> None:
    """On the flat, motors dead, brake released, the chair rolling at 1 m/s; the pin goes
    low. For the engage delay (50 ms) the chair coasts, slowed by its rolling resistance
    and the gears' viscous friction alone (``(R + 2 b v / r^2) / M`` = 0.18 m/s^2; the
    first step is the wheels' and tyres' settling); from the 51st step the brake
    decelerates it: each
    wheel's ``j dw/dt = -T - r F``, the chassis's ``m dv/dt = 2 F - R``, rolling
    (``v = r w``)::

        a = (2 T / r + R) / M = (656.2 + 35.4) / 202.8 = 3.41 m/s^2

    (within the tyres' grip: 328 N each of 547 N). From the speed at the end of the
    delay, v1 = 0.991 m/s, it stops (slower than 1 mm/s) ``v1^2 / (2 a)`` = 0.144 m
    further on, within 1% (the tyres' deflection under the braking force adds up to
    ``T / (r k)`` = 1.6 mm, the gear's viscous friction takes 0.3%), and stays stopped."""
    plant = Plant(BRAKED, use_kernel=use_kernel)
    _roll_freely(plant)
    plant.set_brake(True)
    plant.advance(100)
    v0 = 1.0
    plant.body.velocity = (v0, 0.0)
    plant.s.speed[0] = plant.s.speed[1] = v0 / BRAKED.wheel_radius
    plant.set_brake(False)
    x0 = plant.pose[0]
    xs, vs, engaged = [], [], []
    for _ in range(1000):
        plant.step()
        xs.append(plant.pose[0] - x0)
        vs.append(plant.axle_velocity()[0])
        engaged.append(plant.brake_engaged)
    x, v = np.array(xs), np.array(vs)
    decel = -np.diff(np.concatenate(([v0], v))) / 0.001        # over each step
    m = _m_eff(BRAKED)
    coast = (_rolling(BRAKED, 0.0) + 2.0 * BRAKED.viscous_friction * v0 / BRAKED.wheel_radius**2) / m
    brake = (2.0 * BRAKED.brake_torque / BRAKED.wheel_radius + _rolling(BRAKED, 0.0)) / m
    assert (coast, brake) == pytest.approx((0.18, 3.41), abs=0.005)
    assert engaged.index(True) == 49                           # engaged from the end of step 50
    assert decel[1:50] == pytest.approx(coast, rel=0.01)       # coasting over the delay
    assert decel[60:300] == pytest.approx(brake, rel=0.01)     # braking
    v1 = v[49]
    assert v1 == pytest.approx(v0 - 0.05 * coast, abs=1e-3)
    stopped = int(np.argmax(v < 1e-3))
    assert 0 < stopped < 999
    assert x[stopped] - x[49] == pytest.approx(v1**2 / (2.0 * brake), rel=0.01)
    assert np.all(np.abs(v[stopped:]) < 1e-2) and abs(x[-1] - x[stopped]) < 2e-3


@BACKENDS
def test_too_weak_for_the_grade_it_slips_at_the_acceleration_its_torque_leaves(
        use_kernel: bool) -> None:
    """The heaviest chair facing straight down 1:8 with a 10 N m brake (holding takes
    24.1 N m), motors dead, from rest: its speed after 2 s.

    The wheels turn against the brake's ``T`` each (it slips), so the first free-roll
    equation (tests/plant/test_terrain.py) with ``2 T / r`` more drag::

        M dv/dt = m g sin t - R - 2 T / r - (2 b / r^2) v
        v(t) = (A / B) (1 - exp(-B t)),   A = (m g sin t - R - 2 T / r) / M

    316.4 - 52.8 - 131.2 N on 272.8 kg: A = 0.485 m/s^2, v(2 s) = 0.964 m/s. Tolerance
    0.5% (the plant's rolling resistance fades below 1 cm/s: 0.3% faster). The full
    50 N m would hold it: v would be 0."""
    weak = ChairParams(parking_brake=True, occupant_mass=150.0, brake_torque=10.0)
    t = math.atan(1.0 / 8.0)
    m = _m_eff(weak)
    a = (weak.mass * G * math.sin(t) - _rolling(weak, t) - 2.0 * weak.brake_torque / weak.wheel_radius) / m
    b = 2.0 * weak.viscous_friction / (weak.wheel_radius**2 * m)
    expected = a / b * (1.0 - math.exp(-b * 2.0))
    assert (a, expected) == pytest.approx((0.485, 0.964), abs=0.001)
    plant = Plant(weak, terrain=Terrain(ONE_IN_8, 0.0), use_kernel=use_kernel)
    _roll_freely(plant)
    plant.advance(2000)
    assert plant.brake_engaged
    assert plant.axle_velocity()[0] == pytest.approx(expected, rel=0.005)
    assert plant.left.speed * weak.wheel_radius == pytest.approx(plant.axle_velocity()[0], rel=1e-3)  # rolls


@BACKENDS
def test_a_slipping_brake_sums_with_the_shorted_motors_braking(use_kernel: bool) -> None:
    """As the weak brake above, but duty 0 (the driver shorts each motor: ``-k2 w`` of
    back-EMF braking, tests/plant/test_terrain.py's creep): the speed after 6 s, the
    terminal speed where both brakes balance the grade::

        m g sin t - R - 2 T / r - 2 (k2 + b) v / r^2 = 0
        v = r^2 (m g sin t - R - 2 T / r) / (2 (k2 + b)) = 0.318 m/s

    reached with the time constant ``M r^2 / (2 (k2 + b))`` = 0.66 s (6 s is 9 of them),
    below the speed where the shorted motors reach the current limit (0.44 m/s).
    Tolerance 0.1%."""
    weak = ChairParams(parking_brake=True, occupant_mass=150.0, brake_torque=10.0)
    t = math.atan(1.0 / 8.0)
    ke = weak.motor_constant
    k2 = weak.gear_ratio**2 * weak.gear_efficiency * ke**2 / weak.armature_resistance
    pull = weak.mass * G * math.sin(t) - _rolling(weak, t) - 2.0 * weak.brake_torque / weak.wheel_radius
    expected = weak.wheel_radius**2 * pull / (2.0 * (k2 + weak.viscous_friction))
    assert expected == pytest.approx(0.318, abs=0.001)
    assert expected < weak.current_limit_speed
    plant = Plant(weak, terrain=Terrain(ONE_IN_8, 0.0), use_kernel=use_kernel)
    plant.set_drive(0, 1, 0, 1)
    plant.advance(6000)
    assert plant.axle_velocity()[0] == pytest.approx(expected, rel=0.001)


@BACKENDS
def test_without_a_parking_brake_set_brake_does_nothing(use_kernel: bool) -> None:
    """The seed's chair (no ``parking_brake``): the pin, low or high, changes nothing;
    motors dead on 4 degrees, the chair rolls from the start, step for step as one whose
    pin was never set, and ``brake_engaged`` is False throughout."""
    plant = Plant(terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    plain = Plant(terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    for p in (plant, plain):
        _roll_freely(p)
    assert not plant.brake_engaged
    for level in (False, True, False):
        plant.set_brake(level)
        for p in (plant, plain):
            p.advance(300)
        assert not plant.brake_engaged
        assert plant.pose == plain.pose
    assert plant.axle_velocity()[0] > 0.3


@settings(max_examples=10, deadline=None)
@given(friction=st.sampled_from([0.05, 0.3, 0.8]), torque=st.sampled_from([5.0, 50.0]),
       steps=st.lists(st.tuples(st.integers(0, 255), st.integers(0, 1), st.integers(0, 255),
                                st.integers(0, 1), st.booleans(), st.integers(1, 400)),
                      min_size=1, max_size=8))
@example(friction=0.05, torque=5.0,                 # wheels spinning on a wet floor, then braked:
         steps=[(120, 1, 120, 1, True, 400), (120, 1, 120, 1, False, 300)])   # tyre and brake slip
def test_the_kernel_brakes_as_the_reference_does(friction: float, torque: float, steps) -> None:
    """Drive, brake pin and how long each lasts (ms, so the pin may change back within
    its delay), on a 6 degree grade, dry to wet, with a strong brake and a weak one: the
    C kernel's motion is the Python reference's."""
    params = ChairParams(parking_brake=True, friction=friction, brake_torque=torque)
    fast = Plant(params, terrain=Terrain(6.0, 30.0))
    ref = Plant(params, terrain=Terrain(6.0, 30.0), use_kernel=False)
    assert fast.uses_kernel
    for *drive, released, ms in steps:
        for p in (fast, ref):
            p.set_drive(*drive)
            p.set_brake(released)
            p.advance(ms)
        assert fast.brake_engaged == ref.brake_engaged
    assert fast.pose == pytest.approx(ref.pose, abs=1e-12)
    assert (fast.left.angle, fast.right.angle) == pytest.approx((ref.left.angle, ref.right.angle), abs=1e-12)
    assert (fast.left.speed, fast.right.speed) == pytest.approx((ref.left.speed, ref.right.speed), abs=1e-9)


@BACKENDS
@pytest.mark.parametrize("coil", ["open", "short"])
def test_a_faulty_coil_cannot_release_the_brake(use_kernel: bool, coil: str) -> None:
    """Motors dead, facing down 4 degrees, the pin driven high with the coil open or
    shorted: the spring keeps the brake engaged, so the chair stays put; released
    first and the coil failing then, the brake drops after its engage delay (50 ms)
    and stops the chair. Whole again, the pin high releases it."""
    plant = Plant(BRAKED, terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    _roll_freely(plant)
    plant.set_brake_coil(coil)
    plant.set_brake(True)
    plant.advance(1000)
    assert plant.brake_engaged and plant.left.angle == 0.0
    plant.set_brake_coil(None)
    plant.advance(51)
    assert not plant.brake_engaged
    plant.advance(500)
    assert plant.axle_velocity()[0] > 0.1
    plant.set_brake_coil(coil)
    plant.advance(49)
    assert not plant.brake_engaged
    plant.advance(1)
    assert plant.brake_engaged


@pytest.mark.parametrize(("coil", "pin_high", "low"), [
    (None, False, False), (None, True, False),
    ("open", False, True), ("open", True, False),       # an open load is flagged while off
    ("short", False, False), ("short", True, True),     # an overload while on
])
def test_the_drivers_status_flags_an_open_coil_off_and_a_short_on(coil: str | None, pin_high: bool,
                                                                   low: bool) -> None:
    """The brake driver's status (a smart switch's diagnostic) against the coil and the
    pin; a chair without a brake is an open load on the driver."""
    plant = Plant(BRAKED)
    plant.set_brake_coil(coil)
    plant.set_brake(pin_high)
    assert plant.brake_status_low is low
    bare = Plant()
    bare.set_brake(pin_high)
    assert bare.brake_status_low is (not pin_high)
    with pytest.raises(ValueError, match="brake coil fault"):
        plant.set_brake_coil("melted")


@BACKENDS
def test_the_manual_release_lever_releases_the_brake_whatever_its_pin_and_coil(use_kernel: bool) -> None:
    """Motors dead, facing down 4 degrees, the pin LOW and the coil open: the lever
    pulled releases the brake after its release delay and the chair rolls as one without
    a brake; back, the brake engages after its engage delay and stops it."""
    plant = Plant(BRAKED, terrain=Terrain(4.0, 0.0), use_kernel=use_kernel)
    _roll_freely(plant)
    plant.set_brake_coil("open")
    plant.set_brake_lever(True)
    assert plant.brake_lever
    plant.advance(49)
    assert plant.brake_engaged
    plant.advance(1)
    assert not plant.brake_engaged
    plant.advance(1000)
    assert plant.axle_velocity()[0] > 0.1
    plant.set_brake_lever(False)
    plant.advance(50)
    assert plant.brake_engaged
    plant.advance(2000)
    assert abs(plant.axle_velocity()[0]) < 1e-4          # the tyres' deflection settling
