"""The chair's force model in Python: the readable reference that ``csrc/chair_kernel.c``
repeats line for line (``wcdrive.plant.chair``'s module docstring says what it models).

``set_parameters`` and ``set_terrain`` fill a ``ChairStruct`` from ``ChairParams``, a
heading and a ``Terrain``, for both paths; ``step`` advances the struct and the pymunk
body one step of ``dt`` (the forces of the wheels, their tyres and the casters, then
pymunk's step, then the parking brake's delay), as the kernel's ``step()`` does;
``wheel``, ``stand_still`` and ``grade`` are its parts (the kernel's functions of the
same names), ``deflect`` a tyre patch's deflection, ``clamp`` the kernel's ``clampd``.

Both paths keep their state in the one struct, so a plant can change path between
steps and ``tests/plant/test_plant.py`` can hold the two to the same trajectory. The
constants here are the kernel's ``#define``s of the same names.
"""

from __future__ import annotations

import math

import pymunk

from wcdrive.plant.chair_kernel import ChairStruct
from wcdrive.plant.params import ChairParams, G
from wcdrive.plant.terrain import Terrain

#: rad/s: the swivel friction torque is regularised as ``T tanh(rate / scale)``.
SWIVEL_RATE_SCALE = 0.2
#: m/s: a caster patch sliding sideways faster than this counts as scrubbing.
SCRUB_SLIP = 1e-4
#: s: the brake follows its pin once what is left of its delay is within this (the
#: delay counted down a step at a time ends near 0, either side).
BRAKE_SLACK = 1e-9


def set_parameters(s: ChairStruct, p: ChairParams, heading: float) -> None:
    """The chair's parameters into ``s`` (the motor's and the tyres' coefficients worked
    out here, once, for both paths), its brake engaged (the pin an input, pulled down)
    and its casters at their initial offsets from ``heading``."""
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
    s.th_res, s.th_cap, s.t_amb = p.winding_thermal_resistance, p.winding_heat_capacity, p.ambient_temp
    s.temp[0] = s.temp[1] = p.ambient_temp
    s.bat_e0, s.bat_e1, s.bat_r = p.battery_empty_voltage, p.battery_full_voltage, p.battery_resistance
    s.bat_cap = p.battery_capacity_ah * 3600.0
    s.soc = p.battery_charge
    s.bat_v = s.bat_e0 + (s.bat_e1 - s.bat_e0) * s.soc
    s.caster_heading[0] = heading + p.caster_initial_offsets[0]
    s.caster_heading[1] = heading + p.caster_initial_offsets[1]


def set_terrain(s: ChairStruct, p: ChairParams, terrain: Terrain, body: pymunk.Body) -> None:
    """The terrain's grades into ``s`` (sines and cosines worked out here, once, for both
    paths), and the normal loads for the starting pose (``body``'s)."""
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
    x, y = body.position
    grade(s, x, y, math.cos(body.angle), math.sin(body.angle))


def grade(s: ChairStruct, x: float, y: float, cs: float, sn: float) -> tuple[float, float]:
    """The floor under the axle midpoint (x, y), the chassis heading (cos, sin): sets the
    normal loads (``ChairParams.grade_loads``) and returns the grade's pull on the
    chassis, world frame (N)."""
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
    casters = clamp(casters, 0.0, normal)
    s.n_drive = 0.5 * (normal - casters)
    s.n_caster = 0.5 * casters
    return pull * s.down_c, pull * s.down_s


def wheel(s: ChairStruct, i: int, ground: float, dt: float) -> float:
    """Implicit step of one wheel against the ground speed under it; returns the
    forward force on the chassis less rolling resistance.

    The tyre's force is its patch's, ``k z + c s`` (``deflect``), with the deflection
    at the step's end, ``z + s dt``: linear in the slip ``s = r w - ground``, so
    ``f0 + ce s`` with ``f0 = k z`` and ``ce = c + k dt``, solved with the wheel. An
    engaged brake first asks what holding the wheel still takes, ``tb``: with the
    wheel at rest its equation, ``j (w - speed) / dt = motor - r F + tb``, at the
    tyre's and the stalled motor's torques; within ``brake_torque`` the wheel stands
    still (as a locked one), else the brake's ``brake_torque`` with that sign joins
    the wheel's torques."""
    r, c, j_dt, b = s.r, s.c_long, s.j / dt, s.b
    k = s.k_long
    ce = c + k * dt
    f0 = k * s.defl[i]
    volts, speed = s.volts[i], s.speed[i]
    fmax = s.mu[i] * s.n_drive
    if s.locked[i]:
        return stand_still(s, i, clamp(f0 + ce * -ground, -fmax, fmax), ground, fmax, dt)
    tb = 0.0
    if s.brake_engaged:
        hold = clamp(f0 + ce * -ground, -fmax, fmax)
        stall = 0.0 if s.dead[i] else clamp(s.k1 * volts, -s.tau_max, s.tau_max)
        tb = r * hold - j_dt * speed - stall
        if abs(tb) <= s.brake_torque:
            return stand_still(s, i, hold, ground, fmax, dt)
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
        s.defl[i] = deflect(s.defl[i], s.slip[i], fmax * s.inv_k_long, dt)
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
    s.defl[i] = deflect(s.defl[i], s.slip[i], fmax * s.inv_k_long, dt)
    return force - rr


def stand_still(s: ChairStruct, i: int, force: float, ground: float, fmax: float, dt: float) -> float:
    """The wheel stands still over the step (locked, or held by the brake): its patch
    holds or slides with ``force`` against the ground speed under it; its motor is
    stalled (no current when dead). Returns the force (no rolling resistance)."""
    s.speed[i] = 0.0
    s.current[i] = 0.0 if s.dead[i] else clamp(s.volts[i] / s.res, -s.i_max_r / s.res, s.i_max_r / s.res)
    s.slip[i] = -ground
    s.force[i] = force
    s.defl[i] = deflect(s.defl[i], -ground, fmax * s.inv_k_long, dt)
    return force


def step(s: ChairStruct, body: pymunk.Body, space: pymunk.Space, dt: float) -> None:
    """One step of ``dt``: the forces on ``body`` from the state in ``s``, pymunk's step
    of ``space``, the time and the parking brake's delay."""
    battery(s, dt)
    b = body
    vx, vy = b.velocity
    th = b.angle
    w = b.angular_velocity
    cs, sn, xg = math.cos(th), math.sin(th), s.cog_x
    ax, ay = vx + w * xg * sn, vy - w * xg * cs
    u = ax * cs + ay * sn
    lat = -ax * sn + ay * cs
    if s.terrain:
        x, y = b.position
        gx, gy = grade(s, x, y, cs, sn)
    half = s.half_base
    f_left = wheel(s, 0, u - w * half, dt)
    f_right = wheel(s, 1, u + w * half, dt)
    fx_b, fy_b = f_left + f_right, 0.0
    torque_axle = (f_right - f_left) * half
    k_lat = s.k_lat
    ce_lat = s.c_lat + k_lat * dt
    for i in range(2):
        # the patch sideways as along (wheel), within what the friction circle leaves
        lim = s.mu[i] * s.n_drive
        room = math.sqrt(max(0.0, lim * lim - s.force[i] * s.force[i]))
        fy_b += clamp(k_lat * s.defl_lat[i] + ce_lat * -lat, -room, room)
        s.defl_lat[i] = deflect(s.defl_lat[i], -lat, room * s.inv_k_lat, dt)
    xc, d, n_c = s.caster_x, s.trail, s.n_caster
    scrubbing = False
    for i in range(2):
        yc = s.caster_y if i == 0 else -s.caster_y
        pu, pv = u - w * yc, lat + w * xc
        psi = s.caster_heading[i] - th
        ce, se = math.cos(psi), math.sin(psi)
        along_n = -pu * se + pv * ce
        rate = clamp(along_n / d, -s.swivel_max, s.swivel_max)
        side_slip = along_n - d * rate
        limit = s.mu_c * n_c
        f_swivel = -s.swivel_friction * math.tanh(rate / SWIVEL_RATE_SCALE) / d
        f_side = clamp(f_swivel - s.c_caster * side_slip, -limit, limit)
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
    space.step(dt)
    s.time += dt
    if s.has_brake and s.brake_engaged == s.brake_pin:
        # the brake is yet to follow its pin (released is pin 1, engaged 0)
        s.brake_wait -= dt
        if s.brake_wait <= BRAKE_SLACK:
            s.brake_engaged = 1 - s.brake_pin
    heat(s, dt)


def battery(s: ChairStruct, dt: float) -> None:
    """The battery a step of ``dt`` on, before the forces: its terminal voltage
    ``bat_v`` (the open-circuit voltage, linear in the state of charge between
    ``bat_e0`` and ``bat_e1``, less ``bat_r`` times the driver's input current of the last
    step, each motor's current times its duty), the motors' volts (``duty`` times it) and
    the charge drawn over the step (regenerative braking gives some back). No model with
    ``bat_cap`` 0: the volts stay as ``set_drive`` set them."""
    if s.bat_cap <= 0.0:
        return
    drawn = s.duty[0] * s.current[0] + s.duty[1] * s.current[1]
    s.bat_v = s.bat_e0 + (s.bat_e1 - s.bat_e0) * s.soc - s.bat_r * drawn
    s.volts[0] = s.duty[0] * s.bat_v
    s.volts[1] = s.duty[1] * s.bat_v
    s.soc = clamp(s.soc - drawn * dt / s.bat_cap, 0.0, 1.0)


def heat(s: ChairStruct, dt: float) -> None:
    """Each motor's winding a step of ``dt`` on: one thermal mass (``th_cap``) heated by
    its copper loss ``I^2 R`` and cooled through ``th_res`` to ambient (explicit Euler;
    its time constant, 900 s by default, dwarfs the step). No model with ``th_cap`` 0."""
    if s.th_cap > 0.0:
        for i in range(2):
            loss = s.current[i] * s.current[i] * s.res
            s.temp[i] += dt * (loss - (s.temp[i] - s.t_amb) / s.th_res) / s.th_cap


def clamp(v: float, lo: float, hi: float) -> float:
    """``v`` within ``lo`` and ``hi`` (the kernel's ``clampd``)."""
    return hi if v > hi else (lo if v < lo else v)


def deflect(z: float, slip: float, most: float, dt: float) -> float:
    """A tyre patch's deflection ``z`` (m) after a step of ``dt`` at ``slip`` (m/s): it
    integrates the slip, held within ``most`` (the friction limit over the spring's
    stiffness), where the patch slides instead."""
    return clamp(z + slip * dt, -most, most)
