"""The Eddie robot as a configuration of the pymunk chair, with its range sensors.

``eddie_params(wheel_separation=0.3)``: the chair model (``wcdrive.plant.Plant``) with
Eddie's figures. From the seed: 36 positions per wheel revolution, 6-inch tyres
(radius 0.0762 m), wheel separation 0.3 m (the seed's driver; a parameter: the source's
``POSITIONS_PER_ROTATION = 186`` implies 0.395 m, docs/eddie.md). Assumed, for a
robot of Eddie's size (an 18 kg base with 12 V gear motors), not measured: the mass,
the drive train (top speed 1.0 m/s at full power on the flat) and the tyres.

Walls are pymunk static segments in the plant's ``space`` (``add_wall``), and a
``wcdrive.plant.world.World`` (a scenario's ``[world]``: a ROS map, walls, boxes,
circles), which the sensors see through its ray cast (``World.cast``); the chassis
has no shape, so walls stop only the sensors' rays, not the robot (a collision is
a test failure, not a simulated event).

Sensors (``RangeSensors``), documented in docs/eddie.md:

* two PING))) ultrasonic sensors (pins 0 and 1, facing forward, 0.06 m either side of
  the centre line, 0.2 m ahead of the axle): the nearest wall hit within a 15-degree
  half-angle cone (three rays), 0.02 to 3.0 m, Gaussian noise of 3 mm + 1 % of the
  range; beyond 3.0 m no echo;
* three Sharp GP2Y0A21-style IR sensors on ADC channels 1, 2, 3 (the seed's AD1..AD3,
  left, centre, right; 30 degrees apart): one ray each, 0.10 to 0.80 m, output
  ``(27.86 / d_cm) ** (1 / 1.15)`` volts (a fit to the datasheet curve: 2.4 V at 10 cm,
  0.4 V at 80 cm), 0.25 V beyond, falling linearly to 0 V below 10 cm (the real
  sensor's ambiguous fold-back), noise 15 mV; read by a 10-bit MCP3008 with a 5 V
  reference and reported on 12 bits (``<< 2``, as the firmware's MCP3208 driver
  reads it). The other ADC channels read 0.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pymunk

from wcdrive.eddie.geometry import (
    ADC_VREF,
    IR_MOUNTS,
    IR_NOISE_V,
    PING_HALF_ANGLE,
    PING_MOUNTS,
    PING_RANGE,
    POSITIONS_PER_REV,
    WHEEL_RADIUS,
    WHEEL_SEPARATION,
    Mount,
    ir_volts,
)
from wcdrive.plant.params import ChairParams
from wcdrive.plant.world import World


def eddie_params(wheel_separation: float = WHEEL_SEPARATION, **changes: Any) -> ChairParams:
    """Eddie's figures in the chair model's parameters (module docstring)."""
    base = ChairParams(
        wheelbase=wheel_separation, wheel_radius=WHEEL_RADIUS, counts_per_rev=POSITIONS_PER_REV,
        top_wheel_speed=1.0 / WHEEL_RADIUS, supply_voltage=12.0, current_limit=8.0,
        chair_mass=18.0, occupant_mass=2.0, length=0.45, width=0.45,
        cog_ahead_of_axle=0.02, caster_ahead_of_axle=0.18, caster_half_track=0.05,
        caster_trail=0.02, caster_max_swivel_rate=20.0, caster_swivel_friction=0.02,
        caster_initial_offsets=(0.02, -0.015),
        tyre_stiffness=5000.0, lateral_stiffness=3000.0, caster_stiffness=2000.0,
        gear_ratio=30.0, armature_resistance=2.0, wheel_inertia=0.0015, rotor_inertia=2e-6,
        viscous_friction=0.002,
    )
    return dataclasses.replace(base, **changes)


def add_wall(space: pymunk.Space, a: tuple[float, float], b: tuple[float, float]) -> pymunk.Segment:
    """A static wall segment from ``a`` to ``b`` (m) that the range sensors see."""
    wall = pymunk.Segment(space.static_body, a, b, 0.01)
    space.add(wall)
    return wall


class RangeSensors:
    """The PING))) and IR sensors of the module docstring, against the walls in
    ``space`` and the ``world`` (the nearer of the two); deterministic for a seed."""

    def __init__(self, space: pymunk.Space, seed: int = 0, world: World | None = None) -> None:
        self.space = space
        self.world = world
        self._rng = np.random.default_rng(seed + 1001)

    def _ray(self, pose: tuple[float, float, float], mount: Mount, extra: float, reach: float
             ) -> float | None:
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        ox, oy = x + mount.ahead * c - mount.left * s, y + mount.ahead * s + mount.left * c
        a = th + mount.yaw + extra
        end = (ox + reach * math.cos(a), oy + reach * math.sin(a))
        hit = self.space.segment_query_first((ox, oy), end, 0.0, pymunk.ShapeFilter())
        best = math.inf if hit is None else hit.alpha * reach
        if self.world is not None:
            best = min(best, float(self.world.cast(np.array([ox, oy]), np.array([a]), reach)[0]))
        return None if math.isinf(best) else best

    def ping(self, pose: tuple[float, float, float]) -> dict[int, float | None]:
        """Each PING))) pin's measured distance (m), None without an echo in range."""
        out: dict[int, float | None] = {}
        for pin, mount in PING_MOUNTS.items():
            hits = [h for h in (self._ray(pose, mount, e, PING_RANGE[1] + 0.5)
                                for e in (-PING_HALF_ANGLE, 0.0, PING_HALF_ANGLE)) if h is not None]
            if not hits:
                out[pin] = None
                continue
            d = min(hits)
            d += float(self._rng.normal(0.0, 0.003 + 0.01 * d))
            out[pin] = d if PING_RANGE[0] <= d <= PING_RANGE[1] else None
        return out

    def adc(self, pose: tuple[float, float, float]) -> list[int]:
        """The eight ADC channels (12-bit counts): IR sensors on 1..3, 0 elsewhere."""
        values = [0] * 8
        for channel, mount in IR_MOUNTS.items():
            volts = ir_volts(self._ray(pose, mount, 0.0, 1.5)) + float(self._rng.normal(0.0, IR_NOISE_V))
            counts10 = min(max(int(volts / ADC_VREF * 1024.0), 0), 1023)
            values[channel] = counts10 << 2
        return values
