"""The model plant identification fits: ``simulate(p, run)`` re-simulates a ``Run`` from
rest with the chair ``p``, driven by its recorded duty tick by tick, and
``residuals(p, runs)`` are the wheels' mean speeds over each tick interval, simulated
less measured (rad/s), weighed less and less by the fit beyond ``ROBUST_SCALE``;
``with_motor_constant``, ``apply`` and ``value`` put the fitted figures on a
``ChairParams`` and read them back.

Residuals of mean speeds over whole intervals make the encoder's quantisation one count
over an interval, and a dropped tick only widens an interval; and the equation of
motion is the plant's own:

* On the floor ``simulate`` runs ``wcdrive.plant.chair.Plant`` itself (body, tyres,
  casters), 1 ms steps, the duty of tick k from ``millis[k]`` to ``millis[k+1]``.
* On blocks the drive tyres touch nothing; the wheel is the plant's wheel with no tyre
  force (``block_wheel_step``: the kernel's implicit step, ``j dw/dt = tau - b w`` with
  ``tau = Kt (V - Ke G w) / R`` held to the driver's current limit). The plant cannot be
  used for this: with no grip (``friction = 0``) its wheel step takes the current limit
  it decided with the tyre gripping, and a wheel in the air then runs away beyond its
  no-load speed (docs/bench.md, "Known limits").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from wcdrive.plant.chair import Plant
from wcdrive.plant.identify_run import Run
from wcdrive.plant.params import ChairParams

__all__ = ["DT", "ROBUST_SCALE", "apply", "block_wheel_step", "residuals", "rms", "simulate", "value",
           "with_motor_constant"]

#: s of a plant step.
DT = 0.001
#: rad/s: residuals beyond this weigh less and less (``least_squares``' soft L1 loss): a
#: tick stamped late, a lost line's guessed duty, do not steer the fit.
ROBUST_SCALE = 0.1


def block_wheel_step(p: ChairParams, volts: float, speed: float, dt: float = DT) -> float:
    """A wheel on blocks one step of ``dt`` on from ``speed`` (rad/s) at ``volts``: the
    plant's implicit wheel step with no tyre force. The unlimited solution of
    ``j (w - speed) / dt = k1 V - (k2 + b) w``; where its current would pass the limit,
    the limit's torque instead: ``j (w - speed) / dt = +-tau_max - b w``."""
    k = p.motor_constant
    ke_g = k * p.gear_ratio
    k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
    j_dt = p.wheel_total_inertia / dt
    b = p.viscous_friction
    w = (j_dt * speed + k1 * volts) / (j_dt + k1 * ke_g + b)
    if abs(volts - ke_g * w) > p.current_limit * p.armature_resistance:
        tau = math.copysign(p.gear_ratio * p.gear_efficiency * k * p.current_limit, volts - ke_g * w)
        w = (j_dt * speed + tau) / (j_dt + b)
    return w


def simulate(p: ChairParams, run: Run) -> np.ndarray:
    """The wheels' angles (n x 2) at ``run``'s ticks, from rest at its first, driven by
    its duty: on the floor the plant itself, on blocks ``block_wheel_step``."""
    schedule = run.schedule()
    volts_per_duty = (p.battery_voltage or p.supply_voltage) / 255.0
    out = np.zeros((len(run.millis), 2))
    if not run.blocks:
        plant = Plant(p)
        for n, dl, dr, i in schedule:
            plant.set_drive(abs(int(dl)), int(dl >= 0), abs(int(dr)), int(dr >= 0))
            plant.advance(n, DT)
            if i >= 0:
                out[i + 1] = plant.left.angle, plant.right.angle
        return out
    # the kernel's wheel step, inlined (a call per step costs more than the step)
    k = p.motor_constant
    ke_g = k * p.gear_ratio
    k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
    j_dt = p.wheel_total_inertia / DT
    b = p.viscous_friction
    limit_v = p.current_limit * p.armature_resistance
    tau_max = p.gear_ratio * p.gear_efficiency * k * p.current_limit
    free = j_dt + k1 * ke_g + b
    held = j_dt + b
    for side in (0, 1):
        w = theta = 0.0
        for n, dl, dr, i in schedule:
            volts = volts_per_duty * (dl if side == 0 else dr)
            drive = k1 * volts
            for _ in range(n):
                nxt = (j_dt * w + drive) / free
                if abs(volts - ke_g * nxt) > limit_v:
                    nxt = (j_dt * w + math.copysign(tau_max, volts - ke_g * nxt)) / held
                w = nxt
                theta += w * DT
            if i >= 0:
                out[i + 1, side] = theta
    return out


def with_motor_constant(p: ChairParams, k: float) -> ChairParams:
    """``p`` with the ``top_wheel_speed`` that makes its ``motor_constant`` ``k``.
    ``ChairParams.motor_constant`` solves ``V = k G w + R load / (k G eta)`` for ``k`` at
    the top speed ``w``, the load ``L0 + b w`` per wheel (rolling resistance, the
    casters' share, viscous friction); for a given ``k`` that is linear in ``w``:
    ``w = (V k - R L0 / (G eta)) / (G k^2 + R b / (G eta))``."""
    g, eta, res = p.gear_ratio, p.gear_efficiency, p.armature_resistance
    static = (p.rolling_resistance * p.drive_wheel_load
              + p.caster_rolling_resistance * p.caster_load) * p.wheel_radius
    top = ((p.supply_voltage * k - res * static / (g * eta))
           / (g * k * k + res * p.viscous_friction / (g * eta)))
    if not top > 0:
        raise ValueError(f"no top speed gives the motor constant {k}: too small for the loads")
    return dataclasses.replace(p, top_wheel_speed=float(top))


def apply(base: ChairParams, values: dict[str, float]) -> ChairParams:
    """``base`` with the ``FITTED`` figures of ``values``."""
    fields = {n: v for n, v in values.items() if n != "motor_constant"}
    p = dataclasses.replace(base, **fields)                     # type: ignore[arg-type]
    if "motor_constant" in values:
        p = with_motor_constant(p, values["motor_constant"])
    return p


def value(p: ChairParams, name: str) -> float:
    """A ``FITTED`` figure of ``p``."""
    return float(getattr(p, name))


def residuals(p: ChairParams, runs: Sequence[Run]) -> np.ndarray:
    """Simulated less measured mean wheel speeds over every tick interval of every run
    (rad/s), flattened; 0 where ``Run.weights`` leaves an interval out."""
    out = []
    for run in runs:
        sim = simulate(p, run)
        dt = np.diff(run.millis)[:, None] / 1000.0
        err = (np.diff(sim, axis=0) - np.diff(run.angle, axis=0)) / dt * run.weights()[:, None]
        out.append(err.ravel())
    return np.concatenate(out)


def rms(p: ChairParams, run: Run) -> float:
    """The RMS of ``residuals`` for one run (rad/s)."""
    return float(np.sqrt(np.mean(residuals(p, [run]) ** 2)))
