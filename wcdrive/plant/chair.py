"""The chair as a pymunk rigid body with drive wheels, motors and swivel casters.

``Plant.step(dt)`` advances one fixed physics step (1 kHz by default), ``advance(n,
dt)`` several:

* Motors: the driver applies ``duty/255 * 24 V`` with the sign of DIR. Each motor's
  torque is ``Kt (V - Ke G w)/R`` through the gearbox (efficiency, ratio G), limited
  by the driver's current limit, less viscous gear friction.
* Drive wheels: spin dynamics with the wheel and reflected rotor inertia, solved
  implicitly together with the tyre's longitudinal force. The tyre's contact patch is
  a spring and a damper in parallel behind a Coulomb slider: the reset-integrator
  friction model (D. A. Haessig and B. Friedland, "On the modeling and simulation of
  friction", ASME J. Dyn. Sys. Meas. Control 113(3), 1991; the elastic bristle of the
  LuGre and brush tyre models, without their Stribeck and velocity terms). The patch's
  deflection ``z`` integrates the slip ``s`` (tyre surface minus ground, m/s); the force
  is ``k z + c s`` (``tyre_contact_stiffness`` N/m, ``tyre_stiffness`` N per m/s); where
  that would pass ``mu N`` the patch slides at ``mu N``, its deflection held at
  ``mu N / k``. So a wheel that stands still on a grade holds with the deflection
  ``F / k`` (0.39 mm for each wheel's 77 N parked on 1:12) and does not creep; at speed
  the tyre is the regularised Coulomb law it would be without the spring, but for the
  steady slip ``F / c`` (a fraction of a mm/s) that the spring takes over within
  ``c / k`` (0.5 s). The lateral force likewise (``lateral_contact_stiffness``,
  ``lateral_stiffness``), within what the friction circle leaves. Each step takes the
  deflection at its end, so the force is linear in the step's slip and solved with the
  wheel (backward Euler); the chassis's speed under the tyre is the step's start's
  (pymunk's explicit step), so a wheel held still is stable while ``2 (c + k dt) dt / m``
  stays below 2: 1.05 at 1 ms for the default chair, 1.82 for the empty one (110 kg);
  a 2 ms step is too long for a locked wheel, spring or not. So wheels slip when asked
  for more than the floor gives, and hold when not.
* Casters: a trailing contact patch behind each swivel pivot. The caster swings so its
  patch rolls without side slip, as fast as ``caster_max_swivel_rate`` allows; beyond
  that the patch scrubs sideways against ``mu N``. Swinging takes the bearing's
  friction torque, so a swinging caster pushes the chassis sideways with
  ``T / trail`` (a massless caster's torque balance). The patch carries any side force
  by sliding, at ``force / caster_stiffness`` (the tyre's law), or at its excess speed
  once at ``mu N``: that sliding is the scrub (``caster_scrub_energy``, the force times
  the sliding speed), which a pivot makes and straight driving does not. Driving forward keeps the
  casters trailing; reversing makes them swing round (an unstable equilibrium). At rest
  a caster carries no force (its rolling resistance and swivel friction fade below
  1 cm/s and 0.2 rad/s, as the drive wheels' rolling resistance does): a parked chair
  stands on its drive tyres' grip, and the casters neither hold nor creep.
* The floor (``terrain``, a ``wcdrive.plant.terrain.Terrain``; flat by default): on a
  grade ``t`` under the axle midpoint the floor's share of gravity, ``m g sin(t)``
  toward the downhill heading, pulls the chassis at its centre of gravity, and the
  normal loads are ``ChairParams.grade_loads``: ``m g cos(t)`` in all, moved onto the
  casters facing downhill and onto the drive wheels facing uphill by the pull at
  ``cog_height``. They set the tyres' friction limits and rolling resistance. The
  chassis stays planar (pymunk 2D): x, y are the floor's own coordinates.
* The chassis is a pymunk ``Body`` (mass, yaw inertia, centre of gravity ahead of the
  axle) in a ``Space``; the forces above are applied to it each step and pymunk
  integrates it. Walls or obstacles may be added to ``space``.
* Walls (``world``, a ``wcdrive.plant.world.World``; none by default): its segments
  (radius 0) and circles become static shapes, and the chair's footprint
  (``ChairParams.length`` x ``width``, centred ``footprint_ahead_of_axle`` ahead of the
  axle) a box on the chassis, without mass of its own. pymunk's solver keeps the two
  apart: an inelastic contact (elasticity 0, friction ``WALL_FRICTION``) that lets the
  footprint rest at most ``CONTACT_SLOP`` into a wall (more for a few milliseconds after
  an impact: ``CONTACT_BIAS``). Every contact is reported
  (``contacts``, a ``Contacts``): a collision starts when the chair, touching nothing,
  touches the world, and lasts while it touches anything. Without a world the space
  holds the chassis alone, as before.

The force model exists twice: ``_python_step`` here is the readable reference, and
``csrc/chair_kernel.c`` the same lines in C, which calls pymunk's Chipmunk through
function pointers so a step costs well under a microsecond. ``tests/plant/test_plant.py``
checks that both give the same trajectory. Without a C compiler the Python path runs.

The body's position is the drive axle's midpoint, the odometry reference point.

The parking brake (``ChairParams.parking_brake``; off on the seed's chair): an
electromagnetic brake on each drive wheel, released while the firmware drives its pin
high (``set_brake(True)``) and engaged otherwise, as the driver's pull-down holds it with
the pin an input from reset: a new plant's brake is engaged. The brake takes the pin's
state once ``brake_release_delay`` (high) or ``brake_engage_delay`` (low) has passed
since the pin changed, at the end of the step in which that runs out (``brake_engaged``
reads it from then on, and the next step has it); a pin that changes back sooner leaves
the brake as it was. Engaged, it is Coulomb friction on the wheel, up to
``brake_torque``: each step the wheel stays still when the torque that takes (the
tyre's, the motor's at stall, the wheel's own momentum) is within ``brake_torque``, else
it turns against ``brake_torque``, so a moving wheel is slowed by it. It sums with the
motor's torque, and so with a shorted motor's back-EMF braking at duty 0 (``-k2 w``,
nothing at rest: the brake is what holds).

Faults (``set_wheel_locked``, ``set_motor_dead``; scheduled by ``wcdrive.plant.faults``):
a locked wheel does not turn at all, its tyre holds or slides on the floor within ``mu N``; a
dead motor is an open circuit: no torque, no current, no back-EMF braking, the wheel
rolls freely against its gear friction. ``start_motion_log`` records the chassis's
motion after every step (``take_motion_log``), the ground truth of the fault metrics.
"""

from __future__ import annotations

import ctypes
import dataclasses
import heapq
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import pymunk
from pymunk._chipmunk import lib as _chipmunk

from wcdrive._util.native import BuildError, library, record
from wcdrive.plant.params import ChairParams, G
from wcdrive.plant.terrain import MAX_RAMPS, Terrain

if TYPE_CHECKING:
    from wcdrive.plant.world import World

_D = ctypes.c_double
_P = ctypes.c_void_p


class ChairStruct(ctypes.Structure):
    """``chair_t`` of chair_kernel.c: parameters, Chipmunk handles and the state."""

    _fields_ = [(n, _D) for n in ("half_base", "r", "cog_x", "caster_x", "caster_y", "trail",
                                  "swivel_max", "swivel_friction")]
    _fields_ += [("mu", _D * 2)]
    _fields_ += [(n, _D) for n in ("mu_c", "n_drive", "n_caster", "crr", "crr_c", "c_long", "c_lat",
                                  "c_caster", "j", "b", "k1", "k2", "ke_g", "tau_max", "i_max_r",
                                  "res")]
    _fields_ += [(n, _P) for n in ("space", "body", "get_velocity", "get_angle",
                                  "get_angular_velocity", "set_force", "set_torque", "space_step",
                                  "update_position", "update_velocity", "get_damping", "get_gravity",
                                  "get_sleep_threshold", "each_body", "each_constraint", "body_each_shape",
                                  "get_body_type")]
    _fields_ += [(n, _D * 2) for n in ("volts", "angle", "speed", "current", "slip", "force",
                                      "caster_heading")]
    _fields_ += [(n, _D) for n in ("scrub_energy", "scrub_time", "swivel_work", "side_impulse", "time")]
    _fields_ += [(n, ctypes.c_int32 * 2) for n in ("locked", "dead")]
    _fields_ += [("custom_funcs", ctypes.c_int32)]
    _fields_ += [(n, ctypes.c_int32) for n in ("terrain", "n_ramps")]
    _fields_ += [(n, _D) for n in ("mass_g", "cog_h", "n_drive0", "n_caster0", "down_c", "down_s",
                                  "slope_sin", "slope_cos")]
    _fields_ += [(n, _D * MAX_RAMPS) for n in ("ramp_from", "ramp_to", "ramp_sin", "ramp_cos")]
    _fields_ += [("get_position", _P)]
    _fields_ += [(n, _D) for n in ("k_long", "k_lat", "inv_k_long", "inv_k_lat")]
    _fields_ += [(n, _D * 2) for n in ("defl", "defl_lat")]
    _fields_ += [(n, _D) for n in ("brake_torque", "brake_wait")]
    _fields_ += [(n, ctypes.c_int32) for n in ("has_brake", "brake_pin", "brake_engaged")]


#: rad/s: the swivel friction torque is regularised as ``T tanh(rate / scale)``.
SWIVEL_RATE_SCALE = 0.2
#: m/s: a caster patch sliding sideways faster than this counts as scrubbing.
SCRUB_SLIP = 1e-4
#: s: the brake follows its pin once what is left of its delay is within this (the
#: delay counted down a step at a time ends near 0, either side).
BRAKE_SLACK = 1e-9

_KERNEL_SOURCE = Path(__file__).resolve().parent / "csrc" / "chair_kernel.c"
_kernel: ctypes.CDLL | bool | None = None


def load_kernel() -> ctypes.CDLL | None:
    """The C kernel (``chair_advance``, ``gyro_samples``): the one the install built, else
    compiled on first use; None when neither can be had."""
    global _kernel
    if _kernel is None:
        try:
            lib, how = library("wcdrive.plant._chair_kernel", _KERNEL_SOURCE, "chairkernel", ("-lm",),
                               ("-O2", "-ffp-contract=off"))
            lib.chair_advance.argtypes = [ctypes.POINTER(ChairStruct), ctypes.c_int32, _D, _D,
                                          _P, _P, _P]
            lib.chair_advance.restype = None
            lib.gyro_samples.argtypes = [ctypes.c_int32, _P, _P, _P, ctypes.c_int32, _P, _P]
            lib.gyro_samples.restype = ctypes.c_int32
            lib.chair_advance_sampled.argtypes = [ctypes.POINTER(ChairStruct), ctypes.c_int32, _D, _P, _P, _P,
                                                  _P, _P, ctypes.c_int32, _P, _P]
            lib.chair_advance_sampled.restype = ctypes.c_int32
            _kernel = lib
            record("plant kernel", how)
        except (BuildError, OSError) as exc:            # OSError: no writable cache
            record("plant kernel", f"Python ({exc})".splitlines()[0])
            _kernel = False
    return _kernel if isinstance(_kernel, ctypes.CDLL) else None


class KernelSampler(Protocol):
    """What ``Plant.advance_batch`` needs of a sensor that samples the plant's steps in
    the kernel's call (``wcdrive.plant.sensors.Gyro``)."""

    @property
    def kernel_ready(self) -> bool:
        """Whether it can take its samples in the kernel (else ``sample_steps`` is called)."""

    def sample_steps(self, t0: float, dt: float, rates: np.ndarray, rates_at: int | None = None) -> None:
        """Its samples of ``len(rates)`` steps of ``dt`` from ``t0`` with these yaw rates."""

    def kernel_arguments(self, t0: float, steps: int, dt: float) -> tuple[int, int, int, int, int]:
        """``chair_advance_sampled``'s sampler arguments for ``steps`` steps of ``dt``
        from ``t0``: the addresses of its 8 parameters and of its next random draw, the
        most samples, the addresses of the times and values buffers."""

    def kernel_took(self, count: int) -> None:
        """The kernel wrote ``count`` samples (and moved the next time and the bias on)."""


class WheelView:
    """One drive wheel's state, read from the plant."""

    def __init__(self, s: ChairStruct, i: int) -> None:
        self._s, self._i = s, i

    angle = property(lambda self: self._s.angle[self._i], doc="rad, forward +")
    speed = property(lambda self: self._s.speed[self._i], doc="rad/s")
    current = property(lambda self: self._s.current[self._i], doc="A")
    slip = property(lambda self: self._s.slip[self._i], doc="m/s, tyre surface minus ground")
    force = property(lambda self: self._s.force[self._i], doc="N on the chassis, forward +")


#: m: how far the footprint may sink into a wall before the solver pushes it back out
#: (pymunk's ``collision_slop``; its default, 0.1, is meant for pixels).
CONTACT_SLOP = 5e-4
#: The share of the overlap beyond ``CONTACT_SLOP`` left after a second (pymunk's
#: ``collision_bias``): a tenth is taken back every millisecond. The step of an impact
#: may carry the footprint up to its speed times the step into a wall (2.3 mm at
#: 2.5 m/s in 1 ms steps) before the contact is found; 30 ms on it is within 0.2 mm
#: of the slop.
CONTACT_BIAS = 0.9**1000
#: Coulomb friction between the footprint and a wall (a bumper sliding along it; assumed).
WALL_FRICTION = 0.3
#: s: a collision's impact is the normal impulse the world gives over this long from its
#: first touch: the rigid inelastic impact and the spinning wheels' momentum coming
#: through the tyres (a few steps), and little of the push that may follow.
IMPACT_WINDOW = 0.02
#: The collisions ``Contacts.records`` keeps: the first ones, and the largest impacts.
KEEP_FIRST, KEEP_LARGEST = 50, 10


@dataclass
class Contact:
    """One collision (``Contacts``): ``time`` (s) the end of the step in which the chair
    first touched; ``x``, ``y`` (m, map frame) the mean of that step's contact points;
    ``impact`` (N s) the normal impulse over its first ``IMPACT_WINDOW``; ``impulse``
    (N s) the normal impulse over it all and ``duration`` (s) how long it touched, so
    far."""

    time: float
    x: float
    y: float
    impact: float = 0.0
    impulse: float = 0.0
    duration: float = 0.0


class Contacts:
    """The chair's collisions with the world, as pymunk's solver gave them (a collision
    handler on the plant's space, called from within each step on both paths): the
    figures over the run, and ``records`` (at most ``KEEP_FIRST + KEEP_LARGEST + 1``)."""

    def __init__(self) -> None:
        self.count = 0
        """Collisions so far."""
        self.first_time: float | None = None
        """s: the first one's ``time`` (None: none)."""
        self.max_impact = 0.0
        """N s: the largest ``impact``."""
        self.total_impulse = 0.0
        """N s: the world's normal impulse on the chair over the run."""
        self.contact_time = 0.0
        """s: the steps in which the chair touched the world."""
        self._first: list[Contact] = []
        self._largest: list[tuple[float, int, Contact]] = []      # a min-heap by impact
        self._current: Contact | None = None
        self._touching = 0                                          # shapes touched now
        self._step_end = math.nan                                   # of the last step seen

    @property
    def touching(self) -> bool:
        """Whether the chair touches the world after the last step."""
        return self._touching > 0

    def records(self) -> list[Contact]:
        """Copies of the first ``KEEP_FIRST`` collisions, the ``KEEP_LARGEST`` largest
        impacts among the others that have ended, and the one going on, by time."""
        kept = {id(c): c for c in self._first}
        kept.update((id(c), c) for _, _, c in self._largest)
        if self._current is not None:
            kept[id(self._current)] = self._current
        return sorted((dataclasses.replace(c) for c in kept.values()), key=lambda c: c.time)

    def begin(self, time: float, x: float, y: float) -> None:
        """The chair started touching a shape in the step that ends at ``time``, at
        (``x``, ``y``)."""
        self._touching += 1
        if self._touching > 1:
            return
        contact = Contact(time, x, y)
        self._current = contact
        self.count += 1
        if self.first_time is None:
            self.first_time = time
        if len(self._first) < KEEP_FIRST:
            self._first.append(contact)

    def solved(self, time: float, dt: float, impulse: float) -> None:
        """The solver gave one shape's contact ``impulse`` (N s, normal) in the step of
        ``dt`` that ends at ``time``."""
        contact = self._current
        if contact is None:
            return
        if time != self._step_end:
            self._step_end = time
            self.contact_time += dt
            contact.duration = time - contact.time + dt
        self.total_impulse += impulse
        contact.impulse += impulse
        if time - contact.time < IMPACT_WINDOW - 0.5 * dt:
            contact.impact += impulse
            self.max_impact = max(self.max_impact, contact.impact)

    def separate(self) -> None:
        """The chair stopped touching a shape."""
        self._touching -= 1
        contact = self._current
        if self._touching > 0 or contact is None:
            return
        self._current = None
        if self.count > KEEP_FIRST:                # not among the first, which stay
            entry = (contact.impact, self.count, contact)
            if len(self._largest) < KEEP_LARGEST:
                heapq.heappush(self._largest, entry)
            elif entry[0] > self._largest[0][0]:
                heapq.heapreplace(self._largest, entry)


class Plant:
    """The chair of the module docstring: ``set_drive`` is its input, ``step`` and
    ``advance`` move it, ``left``/``right`` (``WheelView``) and the properties read it.
    ``x``, ``y`` and ``heading`` place the axle midpoint at the start; ``terrain``
    is the floor (default flat); ``world`` the walls the chair collides with (module
    docstring; a ValueError if the footprint overlaps them at the start);
    ``use_kernel=False`` takes the Python reference path."""

    def __init__(self, params: ChairParams | None = None, *, x: float = 0.0, y: float = 0.0,
                 heading: float = 0.0, use_kernel: bool = True, terrain: Terrain | None = None,
                 world: World | None = None) -> None:
        self.p = params or ChairParams()
        p = self.p
        self.terrain = terrain or Terrain()
        self.space = pymunk.Space()
        self.body = pymunk.Body(p.mass, p.yaw_inertia)
        self.body.center_of_gravity = (p.cog_ahead_of_axle, 0.0)
        # the angle first: pymunk turns a body about its centre of gravity, which would
        # move the axle midpoint off (x, y)
        self.body.angle = heading
        self.body.position = (x, y)
        self.space.add(self.body)
        self.world = world
        self.contacts = Contacts()
        self.footprint: pymunk.Poly | None = None
        if world is not None:
            self._add_world(world)
        self.s = s = ChairStruct()
        k = p.motor_constant
        s.half_base = 0.5 * p.wheelbase
        s.r = p.wheel_radius
        s.cog_x = p.cog_ahead_of_axle
        s.caster_x = p.caster_ahead_of_axle
        s.caster_y = p.caster_half_track
        s.trail = p.caster_trail
        s.swivel_max = p.caster_max_swivel_rate
        s.swivel_friction = p.caster_swivel_friction
        s.mu[0], s.mu[1] = p.wheel_friction("left"), p.wheel_friction("right")
        s.mu_c = p.caster_friction
        s.n_drive = p.drive_wheel_load
        s.n_caster = p.caster_load
        s.crr, s.crr_c = p.rolling_resistance, p.caster_rolling_resistance
        s.c_long, s.c_lat, s.c_caster = p.tyre_stiffness, p.lateral_stiffness, p.caster_stiffness
        s.k_long, s.k_lat = p.tyre_contact_stiffness, p.lateral_contact_stiffness
        s.inv_k_long = 1.0 / s.k_long if s.k_long > 0.0 else 0.0
        s.inv_k_lat = 1.0 / s.k_lat if s.k_lat > 0.0 else 0.0
        s.j = p.wheel_total_inertia
        s.b = p.viscous_friction
        s.ke_g = k * p.gear_ratio
        s.k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
        s.k2 = s.k1 * s.ke_g
        s.tau_max = p.gear_ratio * p.gear_efficiency * k * p.current_limit
        s.i_max_r = p.current_limit * p.armature_resistance
        s.res = p.armature_resistance
        s.has_brake = 1 if p.parking_brake else 0
        s.brake_engaged = s.has_brake                 # the pin an input, pulled down
        s.brake_torque = p.brake_torque
        s.caster_heading[0] = heading + p.caster_initial_offsets[0]
        s.caster_heading[1] = heading + p.caster_initial_offsets[1]
        self._set_terrain()
        self.left = WheelView(s, 0)
        self.right = WheelView(s, 1)
        self._motion_log: list[np.ndarray] | None = None
        self._log_chunk = np.empty((0, 6))
        self._log_rows = 0
        self._log_at = 0
        self._buf_rates = np.empty(0)
        self._buf_angles = np.empty((0, 2))
        self._buf_at: tuple[int, int] = (0, 0)
        self._kernel = load_kernel() if use_kernel else None
        if self._kernel is not None:
            self._bind_chipmunk()
            self._advance = self._kernel.chair_advance
            self._ref = ctypes.pointer(self.s)

    def _add_world(self, world: World) -> None:
        """The world's static shapes, the footprint on the chassis, and the collision
        handler that fills ``contacts`` (module docstring)."""
        space = self.space
        space.collision_slop = CONTACT_SLOP
        space.collision_bias = CONTACT_BIAS
        static = space.static_body
        shapes: list[pymunk.Shape] = [pymunk.Segment(static, (x0, y0), (x1, y1), 0.0)
                                      for x0, y0, x1, y1 in world.segments.tolist()]
        shapes += [pymunk.Circle(static, r, (cx, cy)) for cx, cy, r in world.circles.tolist()]
        self.footprint = pymunk.Poly(self.body, footprint(self.p))
        for shape in (*shapes, self.footprint):
            shape.elasticity = 0.0
            shape.friction = WALL_FRICTION
        space.add(*shapes, self.footprint)
        hits = space.shape_query(self.footprint)
        if hits:
            x, y = self.body.position
            points = hits[0].contact_point_set.points
            at = points[0].point_b if points else (x, y)
            raise ValueError(f"the chair's footprint at ({x:g}, {y:g}, {math.degrees(self.body.angle):g} "
                             f"deg) overlaps the world near ({at[0]:.3f}, {at[1]:.3f})")
        contacts = self.contacts

        def step_end() -> tuple[float, float]:
            dt = space.current_time_step
            return self.s.time + dt, dt

        def begin(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
            points = arbiter.contact_point_set.points
            n = 2 * len(points) or 1
            contacts.begin(step_end()[0], sum(c.point_a.x + c.point_b.x for c in points) / n,
                           sum(c.point_a.y + c.point_b.y for c in points) / n)

        def post_solve(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
            j, n = arbiter.total_impulse, arbiter.normal
            contacts.solved(*step_end(), abs(j.x * n.x + j.y * n.y))

        def separate(_arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
            contacts.separate()

        space.on_collision(None, None, begin=begin, post_solve=post_solve, separate=separate)

    def _set_terrain(self) -> None:
        """The terrain's grades into the struct (sines and cosines worked out here, once,
        for both paths), and the normal loads for the starting pose."""
        s, p, terrain = self.s, self.p, self.terrain
        s.n_drive0, s.n_caster0 = s.n_drive, s.n_caster
        if terrain.flat:
            return
        s.terrain = 1
        s.mass_g = p.mass * G
        s.cog_h = p.cog_height
        h = terrain.downhill_heading
        s.down_c, s.down_s = math.cos(h), math.sin(h)
        slope = math.radians(terrain.slope_deg)
        s.slope_sin, s.slope_cos = math.sin(slope), math.cos(slope)
        s.n_ramps = len(terrain.ramps)
        for i, ramp in enumerate(terrain.ramps):
            slope = math.radians(ramp.slope_deg)
            s.ramp_from[i], s.ramp_to[i] = ramp.from_x, ramp.to_x
            s.ramp_sin[i], s.ramp_cos[i] = math.sin(slope), math.cos(slope)
        x, y = self.body.position
        self._grade(x, y, math.cos(self.body.angle), math.sin(self.body.angle))

    def _grade(self, x: float, y: float, cs: float, sn: float) -> tuple[float, float]:
        """The floor under the axle midpoint (x, y), the chassis heading (cos, sin): sets the
        normal loads (``ChairParams.grade_loads``) and returns the grade's pull on the
        chassis, world frame (N)."""
        s = self.s
        along = x * s.down_c + y * s.down_s
        g_sin, g_cos = s.slope_sin, s.slope_cos
        for i in range(s.n_ramps):
            if s.ramp_from[i] <= along < s.ramp_to[i]:
                g_sin, g_cos = s.ramp_sin[i], s.ramp_cos[i]
                break
        if g_sin == 0.0:
            s.n_drive, s.n_caster = s.n_drive0, s.n_caster0
            return 0.0, 0.0
        normal = s.mass_g * g_cos
        pull = s.mass_g * g_sin
        casters = (normal * s.cog_x + pull * (cs * s.down_c + sn * s.down_s) * s.cog_h) / s.caster_x
        casters = _clamp(casters, 0.0, normal)
        s.n_drive = 0.5 * (normal - casters)
        s.n_caster = 0.5 * casters
        return pull * s.down_c, pull * s.down_s

    @property
    def normal_loads(self) -> tuple[float, float]:
        """N: the normal force on each drive wheel and on each caster over the last step
        (before any step: at the starting pose)."""
        return self.s.n_drive, self.s.n_caster

    def _bind_chipmunk(self) -> None:
        from pymunk._chipmunk import ffi, lib

        def address(name: str) -> int:
            return int(ffi.cast("uintptr_t", ffi.addressof(lib, name)))

        s = self.s
        s.space = int(ffi.cast("uintptr_t", self.space._space))
        s.body = int(ffi.cast("uintptr_t", self.body._body))
        s.get_velocity = address("cpBodyGetVelocity")
        s.get_angle = address("cpBodyGetAngle")
        s.get_angular_velocity = address("cpBodyGetAngularVelocity")
        s.set_force = address("cpBodySetForce")
        s.set_torque = address("cpBodySetTorque")
        s.space_step = address("cpSpaceStep")
        s.update_position = address("cpBodyUpdatePosition")
        s.update_velocity = address("cpBodyUpdateVelocity")
        s.get_damping = address("cpSpaceGetDamping")
        s.get_gravity = address("cpSpaceGetGravity")
        s.get_sleep_threshold = address("cpSpaceGetSleepTimeThreshold")
        s.each_body = address("cpSpaceEachBody")
        s.each_constraint = address("cpSpaceEachConstraint")
        s.body_each_shape = address("cpBodyEachShape")
        s.get_body_type = address("cpBodyGetType")
        s.get_position = address("cpBodyGetPosition")

    def _custom_funcs(self) -> None:
        """Tells the kernel whether the body has update functions of its own (then it
        steps the whole space, cpSpaceStep, whatever else is in it)."""
        body = self.body
        self.s.custom_funcs = body._velocity_func is not None or body._position_func is not None

    @property
    def uses_kernel(self) -> bool:
        """Whether steps run in the C kernel (False: the Python reference path)."""
        return self._kernel is not None

    # ---- inputs ------------------------------------------------------------------
    def set_drive(self, pwm_left: int, dir_left: int, pwm_right: int, dir_right: int) -> None:
        """The driver inputs as the firmware writes them: duty 0..255, DIR HIGH = forward."""
        v = (self.p.battery_voltage or self.p.supply_voltage) / 255.0
        self.s.volts[0] = v * pwm_left * (1.0 if dir_left else -1.0)
        self.s.volts[1] = v * pwm_right * (1.0 if dir_right else -1.0)

    def set_brake(self, released: bool) -> None:
        """The level of the firmware's brake pin: true (driven high) releases the parking
        brake; false (low, or an input: the driver's pull-down) engages it. The brake
        follows after its delay (module docstring). No effect without
        ``ChairParams.parking_brake``."""
        s = self.s
        pin = 1 if released else 0
        if not s.has_brake or pin == s.brake_pin:
            return
        s.brake_pin = pin
        s.brake_wait = self.p.brake_release_delay if pin else self.p.brake_engage_delay
        if s.brake_wait <= BRAKE_SLACK:
            s.brake_engaged = 1 - pin

    @property
    def brake_engaged(self) -> bool:
        """Whether the parking brake holds the wheels now (it follows its pin after the
        delay); False for a chair without one."""
        return bool(self.s.brake_engaged)

    def set_wheel_locked(self, side: str, locked: bool = True) -> None:
        """Locks the ``"left"`` or ``"right"`` drive wheel (a jammed gearbox: no torque
        turns it, unlike the parking brake): it no longer turns and its tyre holds or
        slides; ``False`` frees it again."""
        self.s.locked[_side_index(side)] = 1 if locked else 0

    def set_motor_dead(self, side: str, dead: bool = True) -> None:
        """Makes a motor an open circuit (a dead driver channel, a cut wire): no torque
        and no back-EMF braking, whatever the drive input; ``False`` restores it."""
        self.s.dead[_side_index(side)] = 1 if dead else 0

    def wheel_locked(self, side: str) -> bool:
        """Whether that drive wheel is locked (``set_wheel_locked``)."""
        return bool(self.s.locked[_side_index(side)])

    def motor_dead(self, side: str) -> bool:
        """Whether that motor is dead (``set_motor_dead``)."""
        return bool(self.s.dead[_side_index(side)])

    # ---- ground truth log ------------------------------------------------------------
    def start_motion_log(self) -> None:
        """From now on every step records ``(time, forward, lateral, yaw rate, volts
        left, volts right)``: the axle midpoint's motion after the step (m/s, m/s,
        rad/s) and the motor voltages over it, read back with ``take_motion_log``."""
        self._motion_log = []
        self._log_rows = 0

    def take_motion_log(self) -> np.ndarray:
        """The steps recorded since the last take, an ``n x 6`` array
        (``start_motion_log``); empty when the log is off."""
        self._close_log_chunk()
        if not self._motion_log:
            return np.zeros((0, 6))
        out = np.concatenate(self._motion_log)
        self._motion_log = []
        return out

    def _close_log_chunk(self) -> None:
        """The rows ``advance_batch`` wrote into its chunk go to the log."""
        if self._log_rows and self._motion_log is not None:
            self._motion_log.append(self._log_chunk[:self._log_rows])
            self._log_chunk = np.empty((0, 6))
            self._log_rows = 0

    def advance_batch(self, n: int, dt: float = 0.001, *, angles: bool = False,
                      sampler: KernelSampler | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``advance(n, dt, record=True, angles=angles)`` for a caller that uses the
        arrays at once (``wcdrive.boards.port_loop``, a control tick's steps): one call
        of the kernel into buffers the plant keeps (the wheel angles, ``0 x 2`` unless
        ``angles``, and the yaw rates are views that the next call overwrites), the
        motion log written in place. A ``sampler`` (the gyro, ``Gyro.sample_steps``)
        takes its samples of these steps in the same call of the kernel."""
        if self._kernel is None or n <= 0:
            t0 = self.s.time
            recorded = self.advance(n, dt, record=True, angles=angles)
            assert recorded is not None
            if sampler is not None:
                sampler.sample_steps(t0, dt, recorded[1])
            return recorded
        if n > self._buf_rates.size:
            self._buf_rates = np.empty(max(n, 2 * self._buf_rates.size, 64))
            self._buf_angles = np.empty((self._buf_rates.size, 2))
            self._buf_at = (_data(self._buf_angles), _data(self._buf_rates))
        motion = None
        if self._motion_log is not None:
            if self._log_rows + n > self._log_chunk.shape[0]:
                self._close_log_chunk()
                self._log_chunk = np.empty((max(n, _LOG_CHUNK), 6))
                self._log_at = _data(self._log_chunk)
            motion = self._log_at + 48 * self._log_rows
            self._log_rows += n
        self._custom_funcs()
        if sampler is None or not sampler.kernel_ready:
            t0 = self.s.time
            self._advance(self._ref, n, dt, t0, self._buf_at[0] if angles else None, self._buf_at[1], motion)
            if sampler is not None:
                sampler.sample_steps(t0, dt, self._buf_rates[:n], self._buf_at[1])
        else:
            args_at, draws_at, most, times_at, values_at = sampler.kernel_arguments(self.s.time, n, dt)
            taken = self._kernel.chair_advance_sampled(self._ref, n, dt, self._buf_at[0] if angles else None,
                                                       self._buf_at[1], motion, args_at, draws_at, most,
                                                       times_at, values_at)
            sampler.kernel_took(taken)
        return (self._buf_angles[:n] if angles else _NO_ANGLES), self._buf_rates[:n]

    # ---- state -------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated seconds stepped so far."""
        return self.s.time

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x, y, heading) of the axle midpoint, ground truth: ``body.position`` and
        ``body.angle`` as pymunk reads them (Chipmunk's cpBodyGetPosition and
        cpBodyGetAngle), without the Vec2d in between (the tick log reads it every tick)."""
        body = self.body._body
        position = _chipmunk.cpBodyGetPosition(body)
        return position.x, position.y, _chipmunk.cpBodyGetAngle(body)

    @property
    def yaw_rate(self) -> float:
        """rad/s, counter-clockwise positive, ground truth."""
        return self.body.angular_velocity

    @property
    def caster_heading(self) -> tuple[float, float]:
        """World heading of each caster's rolling direction (rad)."""
        return self.s.caster_heading[0], self.s.caster_heading[1]

    @property
    def caster_scrub_energy(self) -> float:
        """J dissipated so far by caster patches sliding sideways."""
        return self.s.scrub_energy

    @property
    def caster_scrub_time(self) -> float:
        """s during which a caster patch slid sideways faster than 0.1 mm/s (``SCRUB_SLIP``)."""
        return self.s.scrub_time

    @property
    def caster_swivel_work(self) -> float:
        """J spent swinging the casters against their bearing friction."""
        return self.s.swivel_work

    @property
    def caster_side_impulse(self) -> float:
        """N s: integral of the casters' sideways push on the chassis (both casters)."""
        return self.s.side_impulse

    def axle_velocity(self) -> tuple[float, float]:
        """(forward, lateral) speed of the axle midpoint in m/s."""
        b = self.body
        th = b.angle
        c, s = math.cos(th), math.sin(th)
        vx, vy = b.velocity
        w = b.angular_velocity
        xg = self.p.cog_ahead_of_axle
        ax, ay = vx + w * xg * s, vy - w * xg * c
        return ax * c + ay * s, -ax * s + ay * c

    # ---- dynamics ----------------------------------------------------------------
    def step(self, dt: float = 0.001) -> None:
        """One physics step of ``dt`` s."""
        self.advance(1, dt)

    def advance(self, n: int, dt: float = 0.001, *, record: bool = False, angles: bool = True
                ) -> tuple[np.ndarray, np.ndarray] | None:
        """``n`` steps of ``dt``. With ``record``, returns the wheel angles after each
        step (an ``n x 2`` array, left and right; ``0 x 2`` with ``angles=False``) and
        the yaw rates (``n``)."""
        if n <= 0:
            return (np.empty((0, 2)), np.empty(0)) if record else None
        logging = self._motion_log is not None
        if self._kernel is not None:
            # One call for the n steps; the arrays passed by address (ctypes' own
            # conversions cost more than the steps of a tick).
            wheels = np.empty((n, 2)) if record and angles else _NONE
            rates = np.empty(n) if record else _NONE
            motion = np.empty((n, 6)) if logging else _NONE
            self._custom_funcs()
            self._advance(self._ref, n, dt, self.s.time, _address(wheels), _address(rates),
                          _address(motion))
            if logging:
                assert self._motion_log is not None
                self._close_log_chunk()
                self._motion_log.append(motion)
            if not record:
                return None
            return (wheels if angles else np.empty((0, 2))), rates
        wheel_angles = np.empty((n if record else 0, 2))
        rates = np.empty(n if record else 0)
        motion = np.empty((n if logging else 0, 6))
        t0 = self.s.time
        for k in range(n):
            self._python_step(dt)
            if record:
                wheel_angles[k] = self.s.angle[0], self.s.angle[1]
                rates[k] = self.body.angular_velocity
            if logging:
                forward, lateral = self.axle_velocity()
                motion[k, 1:4] = forward, lateral, self.body.angular_velocity
        if logging:
            assert self._motion_log is not None
            self._close_log_chunk()
            motion[:, 0] = t0 + dt * np.arange(1, n + 1)
            motion[:, 4], motion[:, 5] = self.s.volts[0], self.s.volts[1]
            self._motion_log.append(motion)
        if not record:
            return None
        return (wheel_angles if angles else np.empty((0, 2))), rates

    def _wheel(self, i: int, ground: float, dt: float) -> float:
        """Implicit step of one wheel against the ground speed under it; returns the
        forward force on the chassis less rolling resistance.

        The tyre's force is its patch's, ``k z + c s`` (``_deflect``), with the deflection
        at the step's end, ``z + s dt``: linear in the slip ``s = r w - ground``, so
        ``f0 + ce s`` with ``f0 = k z`` and ``ce = c + k dt``, solved with the wheel. An
        engaged brake first asks what holding the wheel still takes, ``tb``: with the
        wheel at rest its equation, ``j (w - speed) / dt = motor - r F + tb``, at the
        tyre's and the stalled motor's torques; within ``brake_torque`` the wheel stands
        still (as a locked one), else the brake's ``brake_torque`` with that sign joins
        the wheel's torques."""
        s = self.s
        r, c, j_dt, b = s.r, s.c_long, s.j / dt, s.b
        k = s.k_long
        ce = c + k * dt
        f0 = k * s.defl[i]
        volts, speed = s.volts[i], s.speed[i]
        fmax = s.mu[i] * s.n_drive
        if s.locked[i]:
            return self._stand_still(i, _clamp(f0 + ce * -ground, -fmax, fmax), ground, fmax, dt)
        tb = 0.0
        if s.brake_engaged:
            hold = _clamp(f0 + ce * -ground, -fmax, fmax)
            stall = 0.0 if s.dead[i] else _clamp(s.k1 * volts, -s.tau_max, s.tau_max)
            tb = r * hold - j_dt * speed - stall
            if abs(tb) <= s.brake_torque:
                return self._stand_still(i, hold, ground, fmax, dt)
            tb = math.copysign(s.brake_torque, tb)
        rr = s.crr * s.n_drive * math.tanh(ground / 0.01)
        if s.dead[i]:
            # Open circuit: no torque, no current, so no back-EMF term either.
            w = (j_dt * speed + r * ce * ground - r * f0 + tb) / (j_dt + b + r * r * ce)
            force = f0 + ce * (r * w - ground)
            if abs(force) > fmax:
                force = math.copysign(fmax, force)
                w = (j_dt * speed - r * force + tb) / (j_dt + b)
            s.speed[i] = w
            s.angle[i] += w * dt
            s.current[i] = 0.0
            s.slip[i] = r * w - ground
            s.force[i] = force
            s.defl[i] = _deflect(s.defl[i], s.slip[i], fmax * s.inv_k_long, dt)
            return force - rr
        k1v, tau = s.k1 * volts, 0.0
        w = (j_dt * speed + k1v + r * ce * ground - r * f0 + tb) / (j_dt + s.k2 + b + r * r * ce)
        limited = abs(volts - s.ke_g * w) > s.i_max_r
        if limited:
            tau = math.copysign(s.tau_max, volts - s.ke_g * w)
            w = (j_dt * speed + tau + r * ce * ground - r * f0 + tb) / (j_dt + b + r * r * ce)
        force = f0 + ce * (r * w - ground)
        if abs(force) > fmax:
            # The patch slides: the wheel's speed is solved again under the sliding
            # force, and with it whether the motor is at its current limit (a wheel
            # that loses its grip speeds up, its back-EMF takes the current off the limit).
            force = math.copysign(fmax, force)
            w = (j_dt * speed + k1v - r * force + tb) / (j_dt + s.k2 + b)
            limited = abs(volts - s.ke_g * w) > s.i_max_r
            if limited:
                tau = math.copysign(s.tau_max, volts - s.ke_g * w)
                w = (j_dt * speed + tau - r * force + tb) / (j_dt + b)
        s.speed[i] = w
        s.angle[i] += w * dt
        s.current[i] = (volts - s.ke_g * w) / s.res
        if limited or abs(s.current[i]) * s.res > s.i_max_r:
            s.current[i] = math.copysign(s.i_max_r / s.res, volts - s.ke_g * w)
        s.slip[i] = r * w - ground
        s.force[i] = force
        s.defl[i] = _deflect(s.defl[i], s.slip[i], fmax * s.inv_k_long, dt)
        return force - rr

    def _stand_still(self, i: int, force: float, ground: float, fmax: float, dt: float) -> float:
        """The wheel stands still over the step (locked, or held by the brake): its patch
        holds or slides with ``force`` against the ground speed under it; its motor is
        stalled (no current when dead). Returns the force (no rolling resistance)."""
        s = self.s
        s.speed[i] = 0.0
        s.current[i] = 0.0 if s.dead[i] else _clamp(s.volts[i] / s.res, -s.i_max_r / s.res, s.i_max_r / s.res)
        s.slip[i] = -ground
        s.force[i] = force
        s.defl[i] = _deflect(s.defl[i], -ground, fmax * s.inv_k_long, dt)
        return force

    def _python_step(self, dt: float) -> None:
        s = self.s
        b = self.body
        vx, vy = b.velocity
        th = b.angle
        w = b.angular_velocity
        cs, sn, xg = math.cos(th), math.sin(th), s.cog_x
        ax, ay = vx + w * xg * sn, vy - w * xg * cs
        u = ax * cs + ay * sn
        lat = -ax * sn + ay * cs
        if s.terrain:
            x, y = b.position
            gx, gy = self._grade(x, y, cs, sn)
        half = s.half_base
        f_left = self._wheel(0, u - w * half, dt)
        f_right = self._wheel(1, u + w * half, dt)
        fx_b, fy_b = f_left + f_right, 0.0
        torque_axle = (f_right - f_left) * half
        k_lat = s.k_lat
        ce_lat = s.c_lat + k_lat * dt
        for i in range(2):
            # the patch sideways as along (_wheel), within what the friction circle leaves
            lim = s.mu[i] * s.n_drive
            room = math.sqrt(max(0.0, lim * lim - s.force[i] * s.force[i]))
            fy_b += _clamp(k_lat * s.defl_lat[i] + ce_lat * -lat, -room, room)
            s.defl_lat[i] = _deflect(s.defl_lat[i], -lat, room * s.inv_k_lat, dt)
        xc, d, n_c = s.caster_x, s.trail, s.n_caster
        scrubbing = False
        for i in range(2):
            yc = s.caster_y if i == 0 else -s.caster_y
            pu, pv = u - w * yc, lat + w * xc
            psi = s.caster_heading[i] - th
            ce, se = math.cos(psi), math.sin(psi)
            along_n = -pu * se + pv * ce
            rate = _clamp(along_n / d, -s.swivel_max, s.swivel_max)
            side_slip = along_n - d * rate
            limit = s.mu_c * n_c
            f_swivel = -s.swivel_friction * math.tanh(rate / SWIVEL_RATE_SCALE) / d
            f_side = _clamp(f_swivel - s.c_caster * side_slip, -limit, limit)
            s.swivel_work += abs(s.swivel_friction * math.tanh(rate / SWIVEL_RATE_SCALE) * rate) * dt
            s.side_impulse += abs(f_side) * dt
            # The patch carries its side force by sliding (the tyre's law: c_caster N per
            # m/s), the more so once the force is at the friction limit.
            slip = abs(f_side) / s.c_caster
            if abs(f_side) >= limit:
                slip = max(slip, abs(side_slip))
            s.scrub_energy += abs(f_side) * slip * dt
            scrubbing = scrubbing or slip > SCRUB_SLIP
            roll = pu * ce + pv * se
            f_roll = -s.crr_c * n_c * math.tanh(roll / 0.01)
            fxc = f_roll * ce - f_side * se
            fyc = f_roll * se + f_side * ce
            px, py = xc - d * ce, yc - d * se
            fx_b += fxc
            fy_b += fyc
            torque_axle += px * fyc - py * fxc
            s.caster_heading[i] += (w + rate) * dt
        if scrubbing:
            s.scrub_time += dt
        if s.terrain:
            b.force = (fx_b * cs - fy_b * sn + gx, fx_b * sn + fy_b * cs + gy)
        else:
            b.force = (fx_b * cs - fy_b * sn, fx_b * sn + fy_b * cs)
        b.torque = torque_axle - xg * fy_b
        self.space.step(dt)
        s.time += dt
        if s.has_brake and s.brake_engaged == s.brake_pin:
            # the brake is yet to follow its pin (released is pin 1, engaged 0)
            s.brake_wait -= dt
            if s.brake_wait <= BRAKE_SLACK:
                s.brake_engaged = 1 - s.brake_pin


def footprint(params: ChairParams) -> list[tuple[float, float]]:
    """The footprint's corners in the chassis frame (m; x forward from the axle
    midpoint, y to the left), counter-clockwise from the rear right."""
    front = params.footprint_ahead_of_axle + 0.5 * params.length
    rear = params.footprint_ahead_of_axle - 0.5 * params.length
    half = 0.5 * params.width
    return [(rear, -half), (front, -half), (front, half), (rear, half)]


_NONE = np.empty(0)
_NO_ANGLES = np.empty((0, 2))
_NO_ANGLES.flags.writeable = False
#: Rows of motion log ``advance_batch`` writes into one array.
_LOG_CHUNK = 1 << 14


def _address(a: np.ndarray) -> int | None:
    """The address of ``a``'s data for the kernel (None, a NULL, for ``_NONE``)."""
    return a.__array_interface__["data"][0] if a is not _NONE else None


def _data(a: np.ndarray) -> int:
    """The address of ``a``'s data."""
    return int(a.__array_interface__["data"][0])


def _side_index(side: str) -> int:
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', not {side!r}")
    return 0 if side == "left" else 1


def _clamp(v: float, lo: float, hi: float) -> float:
    return hi if v > hi else (lo if v < lo else v)


def _deflect(z: float, slip: float, most: float, dt: float) -> float:
    """A tyre patch's deflection ``z`` (m) after a step of ``dt`` at ``slip`` (m/s): it
    integrates the slip, held within ``most`` (the friction limit over the spring's
    stiffness), where the patch slides instead."""
    return _clamp(z + slip * dt, -most, most)
