"""The chair against a world's walls and posts (``Plant(world=...)``), checked by hand:
a chair driven into a wall stops with its footprint's front edge on it; the impact of
a chair rolling into a wall or a post is its momentum; a chair parked 1 mm off a wall,
or driving past one 1 cm clear, touches nothing; the C kernel steps a space with walls
as the Python reference does, contacts included; the records stay bounded."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.chair import CONTACT_SLOP, KEEP_FIRST, KEEP_LARGEST, Contacts, footprint
from wcdrive.plant.world import World

#: The seed's chair with its casters square, so that it rolls dead straight.
STRAIGHT = dataclasses.replace(ChairParams(), caster_initial_offsets=(0.0, 0.0))
FRONT = STRAIGHT.footprint_ahead_of_axle + 0.5 * STRAIGHT.length      # 0.7 m ahead of the axle
HALF_WIDTH = 0.5 * STRAIGHT.width
WALL_X = 2.0
WALL = World.from_table({"walls": [[WALL_X, -5.0, WALL_X, 5.0]]})
#: kg: the chassis and its spinning wheels and rotors, as the tyres carry them along
M_EFF = STRAIGHT.mass + 2 * STRAIGHT.wheel_total_inertia / STRAIGHT.wheel_radius**2
BOTH = pytest.mark.parametrize("kernel", [True, False], ids=["kernel", "python"])


def _rolling(world: World, x: float, v: float, kernel: bool) -> Plant:
    """A chair coasting at ``v`` m/s along +x from ``x``, its motors open (no braking)."""
    p = Plant(STRAIGHT, x=x, world=world, use_kernel=kernel)
    assert p.uses_kernel == kernel
    for side in ("left", "right"):
        p.set_motor_dead(side)
    p.body.velocity = (v, 0.0)
    p.s.speed[0] = p.s.speed[1] = v / STRAIGHT.wheel_radius
    return p


def _until_contact(p: Plant, steps: int) -> tuple[float, float]:
    """Steps until the first contact: the speed before that step (m/s) and the impulse
    the wall gave in it (N s)."""
    for _ in range(steps):
        v = p.body.velocity.x
        p.step()
        if p.contacts.count:
            assert p.contacts.first_time == p.time         # the end of the step it touched in
            return v, p.contacts.total_impulse
    raise AssertionError("no contact")


def test_the_footprint_is_the_length_by_width_box_ahead_of_the_axle() -> None:
    assert footprint(STRAIGHT) == [(-0.3, -0.325), (FRONT, -0.325), (FRONT, 0.325), (-0.3, 0.325)]
    assert FRONT == pytest.approx(0.7)


@pytest.mark.parametrize("heading", [0.0, 1.5707963267948966, -2.5, 3.141592653589793])
def test_the_start_pose_is_the_axle_midpoints(heading: float) -> None:
    p = Plant(x=7.475, y=0.9, heading=heading)
    assert p.pose == pytest.approx((7.475, 0.9, heading), abs=1e-12)
    assert p.axle_velocity() == (0.0, 0.0)


def test_without_a_world_the_space_holds_the_chassis_alone() -> None:
    p = Plant()
    assert not p.space.shapes and p.footprint is None and p.world is None
    p.set_drive(200, 1, 200, 1)
    p.advance(500)
    assert p.contacts.count == 0 and p.contacts.records() == []


def test_the_footprint_adds_no_mass() -> None:
    bare, walled = Plant(STRAIGHT), Plant(STRAIGHT, world=WALL)
    assert len(walled.space.shapes) == 2
    for attr in ("mass", "moment", "center_of_gravity"):
        assert getattr(walled.body, attr) == getattr(bare.body, attr)


@BOTH
def test_driven_into_a_wall_the_front_edge_stops_on_it(kernel: bool) -> None:
    p = Plant(STRAIGHT, world=WALL, use_kernel=kernel)
    p.set_drive(120, 1, 120, 1)
    p.advance(6000)                                   # 1.3 m at about 0.6 m/s, then pushing
    x, y, heading = p.pose
    assert x == pytest.approx(WALL_X - FRONT, abs=1e-3)       # 1.300 m
    assert x <= WALL_X - FRONT + CONTACT_SLOP + 1e-6
    assert abs(y) < 1e-3 and abs(heading) < 1e-3
    assert p.contacts.count == 1 and p.contacts.touching
    contact = p.contacts.records()[0]
    assert contact.x == pytest.approx(WALL_X, abs=1e-3) and contact.y == pytest.approx(0.0, abs=1e-3)
    assert p.axle_velocity()[0] == pytest.approx(0.0, abs=1e-3)


@BOTH
def test_the_impact_on_a_wall_is_the_chairs_momentum(kernel: bool) -> None:
    p = _rolling(WALL, 1.2, 1.0, kernel)
    v, first_step = _until_contact(p, 200)
    assert v == pytest.approx(0.98, abs=0.01)          # slowed a little by rolling resistance
    # the step of the contact stops the rigid chassis (elasticity 0): m v
    assert first_step == pytest.approx(STRAIGHT.mass * v, rel=1e-3)
    p.advance(500)
    # the impact adds the spinning wheels' momentum, which the tyres bring in
    assert p.contacts.max_impact == pytest.approx(M_EFF * v, rel=2e-3)
    assert p.contacts.records()[0].impact == p.contacts.max_impact
    assert p.pose[0] == pytest.approx(WALL_X - FRONT, abs=1e-3)
    assert abs(p.body.velocity.x) < 1e-3               # no bounce


@BOTH
def test_a_fast_impact_sinks_in_a_step_and_comes_back_out(kernel: bool) -> None:
    """At 2.5 m/s the step of the impact carries the front edge 2.3 mm into the wall
    (at most the speed times the step); 30 ms later it is back within 0.2 mm of the
    slop (``CONTACT_BIAS``: pymunk's default leaves 2 mm)."""
    p = _rolling(WALL, 1.2, 2.5, kernel)
    _until_contact(p, 200)
    depth = p.pose[0] + FRONT - WALL_X
    assert 0.5 * CONTACT_SLOP < depth <= 2.5 * 0.001
    p.advance(30)
    assert p.pose[0] + FRONT - WALL_X < CONTACT_SLOP + 2e-4
    assert abs(p.body.velocity.x) < 0.05


@BOTH
def test_a_post_hit_head_on(kernel: bool) -> None:
    post = World.from_table({"circles": [[WALL_X, 0.0, 0.05]]})
    p = _rolling(post, 1.0, 0.8, kernel)
    v, first_step = _until_contact(p, 500)
    assert first_step == pytest.approx(STRAIGHT.mass * v, rel=1e-3)
    p.advance(500)
    assert p.contacts.count == 1
    assert p.contacts.max_impact == pytest.approx(M_EFF * v, rel=2e-3)
    contact = p.contacts.records()[0]
    assert (contact.x, contact.y) == pytest.approx((WALL_X - 0.05, 0.0), abs=1e-3)
    x, y, heading = p.pose
    assert x == pytest.approx(WALL_X - 0.05 - FRONT, abs=1e-3)
    assert abs(y) < 1e-3 and abs(heading) < 1e-3


@BOTH
@pytest.mark.parametrize("side", ["front", "rear", "left", "right"])
def test_parked_1_mm_from_a_wall_touches_nothing(kernel: bool, side: str) -> None:
    gap = 0.001
    wall = {"front": [FRONT + gap, -1, FRONT + gap, 1], "rear": [-0.3 - gap, -1, -0.3 - gap, 1],
            "left": [-1, HALF_WIDTH + gap, 1, HALF_WIDTH + gap],
            "right": [-1, -HALF_WIDTH - gap, 1, -HALF_WIDTH - gap]}[side]
    p = Plant(world=World.from_table({"walls": [wall]}), use_kernel=kernel)
    p.advance(2000)
    assert p.contacts.count == 0 and not p.contacts.touching


@BOTH
def test_driving_past_a_wall_1_cm_clear_touches_nothing(kernel: bool) -> None:
    y_wall = HALF_WIDTH + 0.01
    p = Plant(STRAIGHT, world=World.from_table({"walls": [[-1, y_wall, 6, y_wall]]}), use_kernel=kernel)
    p.set_drive(150, 1, 150, 1)
    lateral = 0.0
    for _ in range(40):
        p.advance(100)
        lateral = max(lateral, abs(p.pose[1]) + abs(p.pose[2]) * FRONT)
    assert p.pose[0] > 3.0
    assert lateral < 1e-3                              # the chair ran straight: 1 cm stayed clear
    assert p.contacts.count == 0


def test_a_footprint_that_starts_in_a_wall_is_an_error() -> None:
    with pytest.raises(ValueError, match=r"footprint at \(1.5, 0, 0 deg\) overlaps the world"):
        Plant(world=WALL, x=1.5)


def test_the_kernel_steps_a_collision_as_the_python_reference() -> None:
    """A chair hits a wall, backs off turning, hits it again at an angle, pushes, spins
    on the spot against it and drives off: the same poses and the same contacts, bit
    for bit, on both paths."""
    world = World.from_table({"walls": [[2.0, -3.0, 2.0, 3.0, -1.0, 3.0]],
                              "boxes": [[1.0, -1.2, 0.4, 0.4, 30]], "circles": [[0.5, 1.6, 0.04]]})
    fast, ref = (Plant(world=world, use_kernel=k) for k in (True, False))
    assert fast.uses_kernel and not ref.uses_kernel
    for drive in [(200, 1, 200, 1), (60, 0, 120, 0), (0, 1, 0, 1), (60, 1, 140, 1), (60, 1, 140, 1),
                  (90, 0, 90, 1), (150, 1, 150, 1)]:
        for p in (fast, ref):
            p.set_drive(*drive)
            p.advance(1500)
        assert fast.pose == ref.pose
    assert fast.contacts.count >= 2
    assert fast.contacts.records() == ref.contacts.records()
    for attr in ("count", "first_time", "max_impact", "total_impulse", "contact_time"):
        assert getattr(fast.contacts, attr) == getattr(ref.contacts, attr)


def test_the_records_keep_the_first_and_the_largest() -> None:
    contacts = Contacts()
    impacts = np.random.default_rng(1).uniform(0.0, 100.0, 500)
    for k, impact in enumerate(impacts):
        t = 0.01 * (k + 1)
        contacts.begin(t, float(k), 0.0)
        contacts.begin(t, float(k), 0.0)                # a second shape in the same touch
        contacts.solved(t, 0.001, impact)
        contacts.separate()
        assert contacts.touching
        contacts.separate()
    assert contacts.count == 500 and not contacts.touching
    records = contacts.records()
    assert len(records) == KEEP_FIRST + KEEP_LARGEST
    assert [r.x for r in records[:KEEP_FIRST]] == list(range(KEEP_FIRST))
    rest = np.sort(impacts[KEEP_FIRST:])[-KEEP_LARGEST:]
    assert sorted(r.impact for r in records[KEEP_FIRST:]) == pytest.approx(rest)
    assert contacts.max_impact == impacts.max()
    assert contacts.total_impulse == pytest.approx(impacts.sum())


#: m: the furthest a footprint may be in a wall: the slop, and a step at top speed
DEEPEST = CONTACT_SLOP + 2.68 * 0.001
ROOM = World.from_table({"walls": [[0.0, 0.0, 3.0, 0.0, 3.0, 3.0, 0.0, 3.0, 0.0, 0.0]]})


@settings(max_examples=12, deadline=None)
@example(drive=[(255, 1, 255, 1)] * 3 + [(255, 1, 0, 0)] * 2 + [(200, 0, 150, 0)] * 3)   # walls ahead, behind
@given(drive=st.lists(st.tuples(st.integers(0, 255), st.integers(0, 1), st.integers(0, 255),
                                st.integers(0, 1)), min_size=1, max_size=8))
def test_in_a_closed_room_the_footprint_stays_inside(drive: list[tuple[int, int, int, int]]) -> None:
    """Any drive in a 3 m x 3 m room: no corner of the footprint ever gets further
    through a wall than the slop and a step at top speed (the impact's step: 2.7 mm),
    and both paths agree bit for bit."""
    fast, ref = (Plant(world=ROOM, x=1.2, y=1.5, use_kernel=k) for k in (True, False))
    corners = np.array(footprint(ChairParams()))
    for d in drive:
        for _ in range(10):
            for p in (fast, ref):
                p.set_drive(*d)
                p.advance(100)
            assert fast.pose == ref.pose
            x, y, th = fast.pose
            c, s = np.cos(th), np.sin(th)
            px = x + c * corners[:, 0] - s * corners[:, 1]
            py = y + s * corners[:, 0] + c * corners[:, 1]
            assert np.all((px > -DEEPEST) & (px < 3 + DEEPEST) & (py > -DEEPEST) & (py < 3 + DEEPEST))
    assert fast.contacts.records() == ref.contacts.records()
