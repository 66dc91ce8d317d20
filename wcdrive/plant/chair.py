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

The force model exists twice: ``Plant._python_step`` (``wcdrive.plant.force_model``) is
the readable reference, and ``csrc/chair_kernel.c`` the same lines in C, which calls
pymunk's Chipmunk through function pointers so a step costs well under a microsecond
(``wcdrive.plant.chair_kernel``). ``tests/plant/test_plant.py`` checks that both give
the same trajectory. Without a C compiler the Python path runs.

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
nothing at rest: the brake is what holds). A faulty coil (``set_brake_coil``) cannot
release it; its manual-release lever (``set_brake_lever``) releases it whatever the pin;
the brake driver's status (``brake_status_low``) flags an open coil while off and a short
while on.

The motors' windings heat (``winding_temps``): each one thermal mass
(``winding_heat_capacity``) heated by its copper loss ``I^2 R`` each step and cooled
through ``winding_thermal_resistance`` to ``ambient_temp`` (figures assumed:
``tests/plant/test_motor_heat.py`` holds both paths to the first-order result worked out
by hand). Nothing reads it back yet: the motor's resistance does not rise with it.

The battery (``battery_capacity_ah``; 0 by default: an ideal supply): the motors see
their duty times its terminal voltage, the open-circuit voltage of its state of charge
less its internal resistance times the driver's input current of the last step, and the
charge drawn runs it down (``battery``; ``tests/plant/test_battery.py``).

Faults (``set_wheel_locked``, ``set_motor_dead``; scheduled by ``wcdrive.plant.faults``):
a locked wheel does not turn at all, its tyre holds or slides on the floor within ``mu N``; a
dead motor is an open circuit: no torque, no current, no back-EMF braking, the wheel
rolls freely against its gear friction. ``start_motion_log`` records the chassis's
motion after every step (``take_motion_log``), the ground truth of the fault metrics.

This module holds ``Plant`` and ``WheelView``; the rest is where its concerns part, and
importable from here too: the kernel's binding (``ChairStruct``, ``load_kernel``,
``KernelSampler``) in ``chair_kernel``, the force model in ``force_model``, the walls
and collisions (``Contacts``, ``footprint``) in ``contacts``, the motion log in
``motion_log``.
"""

from __future__ import annotations

import ctypes
import math
from typing import TYPE_CHECKING

import numpy as np
import pymunk
from pymunk._chipmunk import lib as _chipmunk

from wcdrive.plant.chair_kernel import ChairStruct, KernelSampler, bind_chipmunk, load_kernel
from wcdrive.plant.contacts import (
    CONTACT_BIAS,
    CONTACT_SLOP,
    IMPACT_WINDOW,
    KEEP_FIRST,
    KEEP_LARGEST,
    WALL_FRICTION,
    Contact,
    Contacts,
    add_world,
    footprint,
)
from wcdrive.plant.force_model import BRAKE_SLACK, SCRUB_SLIP, SWIVEL_RATE_SCALE, set_parameters, set_terrain
from wcdrive.plant.force_model import step as reference_step
from wcdrive.plant.motion_log import MotionLog
from wcdrive.plant.params import ChairParams
from wcdrive.plant.terrain import Terrain

if TYPE_CHECKING:
    from wcdrive.plant.world import World

__all__ = ["BRAKE_SLACK", "CONTACT_BIAS", "CONTACT_SLOP", "IMPACT_WINDOW", "KEEP_FIRST", "KEEP_LARGEST",
           "SCRUB_SLIP", "SWIVEL_RATE_SCALE", "WALL_FRICTION", "ChairStruct", "Contact", "Contacts",
           "KernelSampler", "Plant", "WheelView", "footprint", "load_kernel"]


class WheelView:
    """One drive wheel's state, read from the plant."""

    def __init__(self, s: ChairStruct, i: int) -> None:
        self._s, self._i = s, i

    angle = property(lambda self: self._s.angle[self._i], doc="rad, forward +")
    speed = property(lambda self: self._s.speed[self._i], doc="rad/s")
    current = property(lambda self: self._s.current[self._i], doc="A")
    slip = property(lambda self: self._s.slip[self._i], doc="m/s, tyre surface minus ground")
    force = property(lambda self: self._s.force[self._i], doc="N on the chassis, forward +")


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
            self.footprint = add_world(self.space, self.body, p, world, self.contacts, lambda: self.s.time)
        self.s = s = ChairStruct()
        set_parameters(s, p, heading)
        set_terrain(s, p, self.terrain, self.body)
        self.left = WheelView(s, 0)
        self.right = WheelView(s, 1)
        self._motion_log: MotionLog | None = None
        self._brake_pin_high = False
        self._brake_coil: str | None = None
        self._brake_lever = False
        self._buf_rates = np.empty(0)
        self._buf_angles = np.empty((0, 2))
        self._buf_at: tuple[int, int] = (0, 0)
        self._kernel = load_kernel() if use_kernel else None
        if self._kernel is not None:
            bind_chipmunk(s, self.space, self.body)
            self._advance = self._kernel.chair_advance
            self._ref = ctypes.pointer(self.s)

    @property
    def normal_loads(self) -> tuple[float, float]:
        """N: the normal force on each drive wheel and on each caster over the last step
        (before any step: at the starting pose)."""
        return self.s.n_drive, self.s.n_caster

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
        s = self.s
        s.duty[0] = pwm_left / 255.0 * (1.0 if dir_left else -1.0)
        s.duty[1] = pwm_right / 255.0 * (1.0 if dir_right else -1.0)
        if s.bat_cap > 0.0:                 # the battery's terminal voltage (force_model.battery)
            s.volts[0] = s.bat_v * s.duty[0]
            s.volts[1] = s.bat_v * s.duty[1]
            return
        v = (self.p.battery_voltage or self.p.supply_voltage) / 255.0
        s.volts[0] = v * pwm_left * (1.0 if dir_left else -1.0)
        s.volts[1] = v * pwm_right * (1.0 if dir_right else -1.0)

    def set_brake(self, released: bool) -> None:
        """The level of the firmware's brake pin: true (driven high) releases the parking
        brake; false (low, or an input: the driver's pull-down) engages it. The brake
        follows after its delay (module docstring); a faulty coil (``set_brake_coil``)
        keeps it engaged. No effect without ``ChairParams.parking_brake``."""
        self._brake_pin_high = bool(released)
        self._apply_brake()

    def set_brake_coil(self, fault: str | None) -> None:
        """The brake coil's state: None, whole; ``"open"`` or ``"short"``: it cannot
        release the brake (the spring holds it engaged, after the engage delay if it was
        released) and the driver's status flags it (``brake_status_low``)."""
        if fault not in (None, "open", "short"):
            raise ValueError(f"brake coil fault must be None, 'open' or 'short', not {fault!r}")
        self._brake_coil = fault
        self._apply_brake()

    @property
    def brake_coil(self) -> str | None:
        """The coil fault ``set_brake_coil`` set, or None."""
        return self._brake_coil

    @property
    def brake_status_low(self) -> bool:
        """The brake driver's status output (a smart power switch's open-drain
        diagnostic, protocol/spec.toml ``PIN_BRAKE_STATUS``): LOW on an open load while
        the pin is LOW (the switch off), on an overload while it is HIGH. A chair
        without a brake has nothing on the driver's output: an open load."""
        coil = self._brake_coil if self.s.has_brake else "open"
        return (coil == "open" and not self._brake_pin_high) or (coil == "short" and self._brake_pin_high)

    def set_brake_lever(self, pulled: bool) -> None:
        """The brake's manual-release lever: pulled, the brake is released by hand
        whatever its pin and coil (after the release delay; back, it engages after the
        engage delay unless the pin holds it off), and the lever's switch tells the
        board (``brake_lever``: push mode)."""
        self._brake_lever = bool(pulled)
        self._apply_brake()

    @property
    def brake_lever(self) -> bool:
        """Whether the brake's manual-release lever is pulled (``set_brake_lever``)."""
        return self._brake_lever

    def _apply_brake(self) -> None:
        """The brake's pin as the brake sees it: released by a whole coil, or by hand."""
        s = self.s
        pin = 1 if (self._brake_pin_high and self._brake_coil is None) or self._brake_lever else 0
        if not s.has_brake or pin == s.brake_pin:
            return
        s.brake_pin = pin
        s.brake_wait = self.p.brake_release_delay if pin else self.p.brake_engage_delay
        if s.brake_wait <= BRAKE_SLACK:
            s.brake_engaged = 1 - pin

    @property
    def battery(self) -> tuple[float, float]:
        """(V, state of charge 0..1): the battery's terminal voltage over the last step
        and its charge (``ChairParams.battery_capacity_ah``; without a battery model the
        supply's voltage and 1)."""
        if self.s.bat_cap <= 0.0:
            return (self.p.battery_voltage or self.p.supply_voltage), 1.0
        return self.s.bat_v, self.s.soc

    @property
    def winding_temps(self) -> tuple[float, float]:
        """deg C: each motor's winding (left, right), from its copper loss
        (``ChairParams.winding_thermal_resistance`` and ``winding_heat_capacity``)."""
        return self.s.temp[0], self.s.temp[1]

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
        self._motion_log = MotionLog()

    def take_motion_log(self) -> np.ndarray:
        """The steps recorded since the last take, an ``n x 6`` array
        (``start_motion_log``); empty when the log is off."""
        if self._motion_log is None:
            return np.zeros((0, 6))
        return self._motion_log.take()

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
        log = self._motion_log
        motion = log.reserve(n) if log is not None else None
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
        log = self._motion_log
        if self._kernel is not None:
            # One call for the n steps; the arrays passed by address (ctypes' own
            # conversions cost more than the steps of a tick).
            wheels = np.empty((n, 2)) if record and angles else _NONE
            rates = np.empty(n) if record else _NONE
            motion = np.empty((n, 6)) if log is not None else _NONE
            self._custom_funcs()
            self._advance(self._ref, n, dt, self.s.time, _address(wheels), _address(rates),
                          _address(motion))
            if log is not None:
                log.append(motion)
            if not record:
                return None
            return (wheels if angles else np.empty((0, 2))), rates
        wheel_angles = np.empty((n if record else 0, 2))
        rates = np.empty(n if record else 0)
        motion = np.empty((n if log is not None else 0, 6))
        t0 = self.s.time
        for k in range(n):
            self._python_step(dt)
            if record:
                wheel_angles[k] = self.s.angle[0], self.s.angle[1]
                rates[k] = self.body.angular_velocity
            if log is not None:
                forward, lateral = self.axle_velocity()
                motion[k, 1:4] = forward, lateral, self.body.angular_velocity
        if log is not None:
            motion[:, 0] = t0 + dt * np.arange(1, n + 1)
            motion[:, 4], motion[:, 5] = self.s.volts[0], self.s.volts[1]
            log.append(motion)
        if not record:
            return None
        return (wheel_angles if angles else np.empty((0, 2))), rates

    def _python_step(self, dt: float) -> None:
        """One step on the Python reference path (``wcdrive.plant.force_model.step``)."""
        reference_step(self.s, self.body, self.space, dt)


_NONE = np.empty(0)
_NO_ANGLES = np.empty((0, 2))
_NO_ANGLES.flags.writeable = False


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
