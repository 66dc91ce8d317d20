"""The identification's equation of motion against results worked out by hand, before
any fitting: a wheel on blocks reaches ``k1 V / (k2 + b)``, starts at the current
limit's ``tau_max / j`` and spins down exponentially with the motor shorted; on the
floor, full duty gives ``top_wheel_speed`` (what ``motor_constant`` is defined by),
also for the top speed ``with_motor_constant`` solves for."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wcdrive.plant.identify import DT, Run, simulate, with_motor_constant
from wcdrive.plant.params import ChairParams


def _run(duty: list[tuple[float, int]], blocks: bool, tick_ms: int = 50) -> Run:
    """Ticks of ``tick_ms`` with the duty of each (seconds, duty) stage on both wheels."""
    rows = [d for seconds, d in duty for _ in range(round(seconds * 1000 / tick_ms))]
    n = len(rows) + 1
    duties = np.array([*rows, 0], dtype=float)
    return Run(millis=np.arange(n) * tick_ms, duty=np.stack([duties, duties], axis=1),
               angle=np.zeros((n, 2)), blocks=blocks)


def _motor(p: ChairParams) -> tuple[float, float, float, float]:
    """k1 (N m/V), k2 (N m s/rad), tau_max (N m) at the wheel and ke_g (V s/rad), by hand
    from the model's torque Kt (V - Ke G w) / R, Kt = G eta Ke."""
    k = p.motor_constant
    k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
    return k1, k1 * k * p.gear_ratio, p.gear_ratio * p.gear_efficiency * k * p.current_limit, k * p.gear_ratio


def test_on_blocks_a_steady_duty_gives_the_terminal_speed_worked_by_hand() -> None:
    p = ChairParams()
    k1, k2, _, ke_g = _motor(p)
    duty = 35                                   # 3.3 V: below I R = 3.9 V, never at the limit
    volts = p.supply_voltage * duty / 255
    assert volts < p.current_limit * p.armature_resistance
    sim = simulate(p, _run([(2.0, duty)], blocks=True))
    speeds = np.diff(sim, axis=0)[:, 0] / 0.05
    terminal = k1 * volts / (k2 + p.viscous_friction)
    assert terminal == pytest.approx(volts / ke_g, rel=0.01)      # viscous friction: 0.4 %
    assert speeds[-2] == pytest.approx(terminal, rel=1e-9)


def test_on_blocks_a_full_duty_start_is_at_the_current_limit() -> None:
    p = ChairParams()
    _, _, tau_max, ke_g = _motor(p)
    j, b = p.wheel_total_inertia, p.viscous_friction
    sim = simulate(p, _run([(0.1, 255)], blocks=True, tick_ms=50))
    # j dw/dt = tau_max - b w from rest (backward Euler in 1 ms steps, as the plant):
    w = 0.0
    angle = 0.0
    for _ in range(50):
        w = (j / DT * w + tau_max) / (j / DT + b)
        angle += w * DT
    assert abs(p.supply_voltage - ke_g * w) > p.current_limit * p.armature_resistance  # still limited
    assert sim[1, 0] == pytest.approx(angle, rel=1e-12)
    assert w == pytest.approx(tau_max / j * 0.05, rel=0.01)       # about tau_max / j over 50 ms


def test_on_blocks_a_shorted_motor_spins_the_wheel_down_exponentially() -> None:
    p = ChairParams()
    k1, k2, _, _ = _motor(p)
    duty = 30
    volts = p.supply_voltage * duty / 255
    w0 = k1 * volts / (k2 + p.viscous_friction)
    assert w0 * p.gear_ratio * p.motor_constant < p.current_limit * p.armature_resistance  # unlimited
    sim = simulate(p, _run([(2.0, duty), (2.0, 0)], blocks=True))
    at_stop = 40
    # w(t) = w0 exp(-t (k2 + b) / j): the wheel turns w0 j / (k2 + b) more after the stop
    # (exactly so in backward Euler steps too)
    coast = sim[-1, 0] - sim[at_stop, 0]
    assert coast == pytest.approx(w0 * p.wheel_total_inertia / (k2 + p.viscous_friction), rel=1e-6)
    speed = np.diff(sim, axis=0)[:, 0] / 0.05
    tau = p.wheel_total_inertia / (k2 + p.viscous_friction)
    mean_first = w0 * tau * (1 - np.exp(-0.05 / tau)) / 0.05       # the first interval's mean
    assert speed[at_stop] == pytest.approx(mean_first, rel=0.02)


@pytest.mark.parametrize("k_factor", [1.0, 0.77, 1.3])
def test_on_the_floor_full_duty_reaches_the_top_speed_motor_constant_is_set_by(k_factor: float) -> None:
    p = with_motor_constant(ChairParams(), ChairParams().motor_constant * k_factor)
    assert p.motor_constant == pytest.approx(ChairParams().motor_constant * k_factor, rel=1e-12)
    sim = simulate(p, _run([(12.0, 255)], blocks=False))
    speed = (sim[-2, :] - sim[-12, :]) / 0.5
    # full duty on level ground: V = Ke G w + R load / (Kt): the top speed by definition
    assert speed == pytest.approx([p.top_wheel_speed] * 2, rel=0.002)


def test_the_body_is_invisible_on_blocks_and_not_on_the_floor() -> None:
    p = ChairParams()
    # the same motor: ChairParams derives motor_constant from the top speed and the loads
    heavy = with_motor_constant(dataclasses.replace(p, chair_mass=150.0, rolling_resistance=0.03),
                                p.motor_constant)
    run = _run([(1.0, 120), (1.0, 0)], blocks=True)
    assert np.array_equal(simulate(p, run), simulate(heavy, run))
    floor = dataclasses.replace(run, blocks=False)
    assert not np.allclose(simulate(p, floor), simulate(heavy, floor), rtol=0.01)
