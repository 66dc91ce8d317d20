"""The pymunk plant and the closed loop against the seed's numbers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wcdrive.plant import ChairParams, Gyro, Plant, encoder_counts
from wcdrive.plant.terrain import Ramp, Terrain
from wcdrive.sim import runner, scenario
from wcdrive.sim.scenario import Scenario, Segment


def _run(segments, duration_settle: float = 1.0, **chair) -> runner.SimResult:
    sc = Scenario("test", "", tuple(Segment(*s) for s in segments), settle_s=duration_settle, chair=chair)
    return runner.run(sc)


#: The floors the kernel is held to the reference on: flat, a uniform grade across the
#: start heading, and ramp bands (up, then down) the chair drives onto and off.
FLOORS = {"flat": None, "slope": Terrain(6.0, 30.0),
          "ramps": Terrain(0.0, 10.0, (Ramp(0.3, 1.2, -7.0), Ramp(1.5, 2.5, 5.0)))}


@pytest.mark.parametrize("floor", FLOORS)
@settings(max_examples=10, deadline=None)
@given(drive=st.lists(st.tuples(st.integers(0, 255), st.integers(0, 1), st.integers(0, 255),
                                st.integers(0, 1)), min_size=1, max_size=6))
@example(drive=[(255, 1, 255, 1)] * 4 + [(0, 1, 0, 1)] * 2)      # onto the first ramp and beyond
def test_c_kernel_matches_the_python_reference(floor, drive) -> None:
    fast, ref = Plant(terrain=FLOORS[floor]), Plant(use_kernel=False, terrain=FLOORS[floor])
    assert fast.uses_kernel
    for d in drive:
        for p in (fast, ref):
            p.set_drive(*d)
            p.advance(300)
    assert fast.pose == pytest.approx(ref.pose, abs=1e-12)
    assert (fast.left.angle, fast.right.angle) == pytest.approx((ref.left.angle, ref.right.angle), abs=1e-12)
    assert fast.caster_heading == pytest.approx(ref.caster_heading, abs=1e-12)
    assert fast.normal_loads == pytest.approx(ref.normal_loads, abs=1e-9)


def test_full_duty_gives_the_seed_top_speed() -> None:
    p = Plant()
    p.set_drive(255, 1, 255, 1)
    p.advance(20000)
    assert p.left.speed == pytest.approx(17.59, rel=0.002)
    assert p.axle_velocity()[0] == pytest.approx(2.68, rel=0.005)


def test_current_limit_bounds_the_motor_current() -> None:
    p = Plant()
    p.set_drive(255, 1, 255, 1)
    p.advance(5)
    assert abs(p.left.current) <= p.p.current_limit + 1e-9


def test_kinematics_0_5_m_s_with_0_2_rad_s() -> None:
    r = _run([("cmdvel", (0.5, 0.2), 15.0)])
    i = np.searchsorted(r.board.tick_time, 14.5)
    assert r.board.setpoint[i] == pytest.approx((2.91, 3.65), abs=0.005)     # left, right
    assert r.truth.wheel_speed[i] == pytest.approx((2.91, 3.65), abs=0.02)


def test_ramp_takes_0_to_10_rad_s_in_2_s() -> None:
    r = _run([("wheel", (10.0, 10.0), 3.0)])
    start = r.board.tick_time[np.argmax(r.board.setpoint[:, 0] > 0)]
    reached = r.board.tick_time[np.argmax(r.board.setpoint[:, 0] >= 10.0)]
    assert reached - start == pytest.approx(2.0 - 0.05, abs=0.06)     # first step at the first tick


def test_no_windup_overshoot_after_saturation() -> None:
    """Motors rated for 28 V on a 24 V battery cannot reach 17.5 rad/s: the PID
    saturates for seconds, then a step down to 3 rad/s must not undershoot
    (back-calculation). (A battery sagged to 20 V would do it too, but the board's
    low-battery rollback now caps the speed it asks: docs/safety.md, "The battery".)"""
    r = _run([("wheel", (17.5, 17.5), 6.0), ("wheel", (3.0, 3.0), 6.0)], supply_voltage=28.0,
             battery_voltage=24.0)
    t = r.board.tick_time
    saturated = (t > 4.0) & (t < 6.0)
    pwm = np.abs(r.board.pwm[saturated])
    assert np.mean(pwm == 255) > 0.5 and np.all(pwm >= 240)
    after = (t > 6.0) & (t < 12.0)
    assert r.board.measured[after].min() > 3.0 - 0.05          # approaches 3.0 from above, no dip
    late = r.board.measured[(t > 11.0) & (t < 12.0)].mean()
    assert late < r.board.measured[(t > 8.0) & (t < 9.0)].mean() and late < 3.6   # settling from above


def test_slip_turns_wheel_odometry_but_not_the_gyro() -> None:
    r = runner.run(scenario.load("slip_turn"))
    m = r.metrics()
    # 16.5 deg when the watchdog's stop let the chair coast; 7.6 deg since it brakes
    #: the wet wheel slips less on the way to rest.
    assert abs(m["odom_wheel_heading_error_deg"]) > 5.0
    assert abs(m["odom_gyro_heading_error_deg"]) < 1.0
    dry = runner.run(dataclasses.replace(scenario.load("slip_turn"), chair={}))
    assert abs(dry.metrics()["odom_wheel_heading_error_deg"]) < 2.0


def _reverse_start(r: runner.SimResult) -> int:
    """First tick at which the chair moves backwards faster than 0.1 m/s."""
    speed = 0.5 * 0.1524 * r.truth.wheel_speed.sum(axis=1)
    return int(np.argmax(speed < -0.1))


def test_pivot_swings_the_casters_round_before_reversing() -> None:
    """With the pivot the casters have swung past 90 degrees by the time the chair backs
    up; without it they still point forward, so backing up drags them round."""
    pivot = runner.run(scenario.load("reversal_pivot"))
    straight = runner.run(scenario.load("reversal_no_pivot"))
    i, j = _reverse_start(pivot), _reverse_start(straight)
    assert np.all(np.degrees(np.abs(pivot.truth.caster[i])) > 60.0)
    assert np.all(np.degrees(np.abs(straight.truth.caster[j])) < 30.0)
    # Without the pivot the swing happens while reversing: it ends later in the manoeuvre.
    def swung(r: runner.SimResult) -> float:
        k = int(np.argmax(np.all(np.abs(r.truth.caster) > math.radians(150), axis=1)))
        return float(r.board.tick_time[k] - r.board.tick_time[_reverse_start(r)])
    assert swung(pivot) < swung(straight)


def test_encoder_counts_mirror_the_left_wheel() -> None:
    assert encoder_counts(2 * math.pi, 2 * math.pi) == (-10000, 10000)
    assert encoder_counts(0.0, -1e-9) == (0, -1)


def test_gyro_noise_matches_the_bmi085_figure() -> None:
    params = dataclasses.replace(ChairParams(), gyro_bias_walk_dps_per_sqrt_s=0.0)
    g = Gyro(params, seed=1)
    for k in range(4000):
        g.sample(k / 400.0, 0.0)
    rates = np.degrees(np.array(g.rates))
    assert np.std(rates) == pytest.approx(0.014, rel=0.1)


def test_runs_are_deterministic() -> None:
    a = runner.run(scenario.load("l_shape"), seed=3)
    b = runner.run(scenario.load("l_shape"), seed=3)
    assert np.array_equal(a.truth.pose, b.truth.pose) and np.array_equal(a.odometry.gyro, b.odometry.gyro)


@pytest.mark.parametrize("path", scenario.bundled(), ids=lambda p: p.stem)
def test_every_bundled_scenario_loads(path) -> None:
    sc = scenario.load(str(path))
    assert sc.duration > 0 and sc.host_commands()


def test_scenario_errors_are_clear(tmp_path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[[segment]]\ncmdvel = [9.0, 0.0]\nduration = 1\n')
    with pytest.raises(scenario.ScenarioError, match="segment 1"):
        scenario.load(str(bad))
    with pytest.raises(scenario.ScenarioError, match="no scenario"):
        scenario.load("no_such_scenario")


@pytest.mark.simavr
def test_simavr_backend_gives_the_same_firmware_outputs(elf) -> None:
    sc = Scenario("short", "", (Segment("cmdvel", (0.4, 0.3), 1.5), Segment("cmdvel", (-0.3, 0.0), 1.5)),
                  settle_s=0.5)
    r = runner.run(sc, backend="simavr", elf=elf)
    assert r.lockstep.events_compared > 100
    assert r.firmware_differences == 0
    port = runner.run(sc)
    # Not identical (the simavr tick latches counts mid-step), but the same motion.
    assert np.abs(r.truth.pose[-1, :2] - port.truth.pose[-1, :2]).max() < 0.02


def _drive_bits(plant: Plant, seed: int = 5, ticks: int = 80) -> list[bytes]:
    """A random drive, 50 steps a tick through ``advance_batch``; the chassis's state
    and the wheels' after every tick, as raw bytes (bit for bit)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(ticks):
        plant.set_drive(int(rng.integers(0, 256)), int(rng.integers(0, 2)), int(rng.integers(0, 256)),
                        int(rng.integers(0, 2)))
        plant.advance_batch(50, 0.001)
        b = plant.body
        out.append(np.array([*b.position, b.angle, *b.velocity, b.angular_velocity, plant.left.angle,
                             plant.right.angle, *plant.caster_heading]).tobytes())
    return out


def test_a_lone_chassis_steps_as_cpSpaceStep_steps_it() -> None:
    """The kernel calls Chipmunk's two body updates itself when the chassis is alone in
    its space (chair_kernel.c's lone_body); a space with anything else in it goes through
    cpSpaceStep. Both give the same motion bit for bit: here against a space whose second
    body (no shape, far away) makes the kernel take cpSpaceStep."""
    import pymunk

    lone, crowded = Plant(), Plant()
    crowded.space.add(pymunk.Body(1.0, 1.0))
    assert lone.uses_kernel and _drive_bits(lone) == _drive_bits(crowded)


def test_anything_else_in_the_space_takes_cpSpaceStep() -> None:
    """What cpSpaceStep would act on (a shape on the chassis that hits a wall, a
    constraint, a velocity function of the body's own) is not skipped: the kernel's
    motion is the Python reference's (which always steps the space)."""
    import pymunk

    def setups(plant: Plant) -> None:
        plant.body.velocity_func = lambda body, gravity, damping, dt: pymunk.Body.update_velocity(
            body, gravity, 0.5, dt)

    def walls(plant: Plant) -> None:
        plant.space.add(pymunk.Circle(plant.body, 0.4))
        plant.space.add(pymunk.Segment(plant.space.static_body, (0.6, -5.0), (0.6, 5.0), 0.01))

    def swapped(plant: Plant) -> None:             # the chassis out, another body in
        plant.space.remove(plant.body)
        other = pymunk.Body(1.0, 1.0)
        other.velocity = (1.0, 0.0)
        plant.space.add(other)

    def static(plant: Plant) -> None:              # cpSpaceStep integrates no static body
        plant.body.body_type = pymunk.Body.STATIC
        plant.space.gravity = (0.0, -9.81)

    for change in (setups, walls, swapped, static):
        fast, ref = Plant(), Plant(use_kernel=False)
        for p in (fast, ref):
            change(p)
            p.set_drive(200, 1, 200, 1)
            p.advance(2000)
        assert fast.pose == pytest.approx(ref.pose, abs=1e-9), change.__name__
        bodies = [(b.position.x, b.position.y) for b in fast.space.bodies]
        assert bodies == pytest.approx([(b.position.x, b.position.y) for b in ref.space.bodies], abs=1e-9)
    # a shape on the chassis and nothing to hit: cpSpaceStep still moves its bounding box
    boxes = []
    for p in (Plant(), Plant(use_kernel=False)):
        circle = pymunk.Circle(p.body, 0.4)
        p.space.add(circle)
        start = circle.cache_bb().right
        p.set_drive(200, 1, 180, 1)
        p.advance(1500)
        boxes.append(tuple(circle.bb))
    assert boxes[0] == pytest.approx(boxes[1], abs=1e-9) and boxes[0][2] > start + 0.3
    # sleeping on: cpSpaceStep puts a chassis idle for longer than the threshold to
    # sleep (every step's cpBodySetForce wakes it, so only a threshold under a step does)
    asleep = []
    for p in (Plant(), Plant(use_kernel=False)):
        p.space.sleep_time_threshold = 0.0005
        p.space.idle_speed_threshold = 10.0
        p.advance(100)
        asleep.append(p.body.is_sleeping)
    assert asleep == [True, True]
    slowed = Plant()
    setups(slowed)
    slowed.set_drive(200, 1, 200, 1)
    slowed.advance(2000)
    plain = Plant()
    plain.set_drive(200, 1, 200, 1)
    plain.advance(2000)
    assert slowed.pose[0] < 0.9 * plain.pose[0]        # the damping of its own took effect


def test_pose_is_what_pymunk_reads() -> None:
    """``Plant.pose`` reads Chipmunk directly: the same floats as ``body.position`` and
    ``body.angle``, after motion and after the body is moved by hand."""
    p = Plant()
    for d in ((200, 1, 120, 1), (90, 0, 250, 1)):
        p.set_drive(*d)
        p.advance_batch(173)
        b = p.body
        assert p.pose == (b.position.x, b.position.y, b.angle)
    p.body.angle = 2.0
    p.body.position = (3.25, -1.5)
    assert p.pose == (3.25, -1.5, 2.0) == (p.body.position.x, p.body.position.y, p.body.angle)
