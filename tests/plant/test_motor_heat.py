"""The motors' windings heat (``ChairParams.winding_thermal_resistance``,
``winding_heat_capacity``; ``Plant.winding_temps``) against the result worked out by hand.

Each winding is one thermal mass C heated by its copper loss P = I^2 R and cooled through
R_th to ambient: dT/dt = (P - (T - T_amb) / R_th) / C, so at a steady current
T(t) = T_amb + P R_th (1 - exp(-t / tau)), tau = R_th C. Both wheels locked (a jammed
gearbox: the motor stalls, no back-EMF), duty 32 from 24 V: V = 32 / 255 x 24 = 3.012 V,
I = V / R = 10.04 A (under the 13 A limit), P = 30.24 W; with R_th = 2.5 K/W and
C = 360 J/K, tau = 900 s and the rise settles at 75.6 K. Both paths (the C kernel and
the Python reference) are held to it and to each other.
"""

from __future__ import annotations

import math

import pytest

from wcdrive.plant import ChairParams, Plant

P = ChairParams()
VOLTS = 32 / 255 * P.supply_voltage
CURRENT = VOLTS / P.armature_resistance
LOSS = CURRENT**2 * P.armature_resistance
TAU = P.winding_thermal_resistance * P.winding_heat_capacity
RISE = LOSS * P.winding_thermal_resistance


def _stalled(use_kernel: bool) -> Plant:
    plant = Plant(P, use_kernel=use_kernel)
    for side in ("left", "right"):
        plant.set_wheel_locked(side)
    plant.set_drive(32, 1, 32, 1)
    return plant


def test_the_hand_figures() -> None:
    assert VOLTS == pytest.approx(3.012, abs=1e-3)
    assert CURRENT == pytest.approx(10.04, abs=0.01) and CURRENT < P.current_limit
    assert LOSS == pytest.approx(30.24, abs=0.01)
    assert TAU == pytest.approx(900.0) and RISE == pytest.approx(75.6, abs=0.05)


def test_a_stalled_winding_rises_as_the_first_order_model_says() -> None:
    """After tau (900 s) the rise is 63.2 % of 75.6 K, 47.8 K; after 5 tau within 1 %
    of all of it; the current is the stall current; both windings alike. Cooled (duty 0
    from there), it falls back with the same time constant."""
    plant = _stalled(True)
    assert plant.winding_temps == (P.ambient_temp, P.ambient_temp)
    plant.advance(900_000, angles=False)
    assert plant.left.current == pytest.approx(CURRENT, rel=1e-9)
    left, right = plant.winding_temps
    assert left == right
    assert left - P.ambient_temp == pytest.approx(RISE * (1 - math.exp(-1)), rel=1e-3)
    plant.advance(3_600_000, angles=False)
    assert plant.winding_temps[0] - P.ambient_temp == pytest.approx(RISE * (1 - math.exp(-5)), rel=1e-3)
    hot = plant.winding_temps[0] - P.ambient_temp
    plant.set_drive(0, 1, 0, 1)
    plant.advance(900_000, angles=False)
    assert plant.winding_temps[0] - P.ambient_temp == pytest.approx(hot * math.exp(-1), rel=1e-3)


def test_at_the_current_limit_the_winding_would_pass_its_rating() -> None:
    """Stalled at full duty the driver holds 13 A: 50.7 W settles 127 K up, 147 deg C,
    past the class B rating (130): what the firmware's thermal rollback is to prevent."""
    plant = _stalled(True)
    plant.set_drive(255, 1, 255, 1)
    plant.advance(4_500_000, angles=False)                # 5 tau
    assert plant.left.current == pytest.approx(P.current_limit, rel=1e-9)
    settled = P.ambient_temp + P.current_limit**2 * P.armature_resistance * P.winding_thermal_resistance
    assert settled == pytest.approx(146.75, abs=0.01) and settled > P.winding_temp_rating
    expected = (settled - P.ambient_temp) * (1 - math.exp(-5))
    assert plant.winding_temps[0] - P.ambient_temp == pytest.approx(expected, rel=1e-3)


def test_the_reference_heats_as_the_kernel_does() -> None:
    """10 s stalled on each path: the same temperatures (within 1e-12 of each other), and the
    hand figure (0.836 K)."""
    kernel, reference = _stalled(True), _stalled(False)
    kernel.advance(10_000, angles=False)
    reference.advance(10_000, angles=False)
    assert kernel.winding_temps[0] == pytest.approx(reference.winding_temps[0], rel=1e-12)
    rise = kernel.winding_temps[0] - P.ambient_temp
    assert rise == pytest.approx(RISE * (1 - math.exp(-10 / TAU)), rel=1e-3)


def test_without_a_heat_capacity_there_is_no_model() -> None:
    plant = Plant(ChairParams(winding_heat_capacity=0.0))
    plant.set_wheel_locked("left")
    plant.set_drive(100, 1, 0, 1)
    plant.advance(1000, angles=False)
    assert plant.winding_temps == (20.0, 20.0)
