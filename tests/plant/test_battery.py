"""The battery (``ChairParams.battery_capacity_ah`` and its figures; ``Plant.battery``)
against the results worked out by hand.

The motors see their duty d times the terminal voltage V_b = E(q) - R_b I_b, where E is
linear in the state of charge q (``battery_empty_voltage`` to ``battery_full_voltage``)
and I_b = sum(d_i I_i) is the driver's input current; the charge drawn runs q down by
I_b dt / (3600 C). Both wheels locked (no back-EMF) at duty d: I R = d V_b and
V_b = E - 2 d R_b I, so I = d E / (R + 2 d^2 R_b). Full (E = 25.6 V), d = 32/255 =
0.12549, R = 0.3, R_b = 0.05: I = 3.2125 / 0.30157 = 10.652 A, V_b = 25.466 V (a 0.134 V
sag), I_b = 2.673 A; over 60 s the charge falls by 160.4 C, 0.0891 % of 50 Ah (180,000 C).
Both paths (the C kernel, the Python reference) are held to it and to each other.
"""

from __future__ import annotations

import pytest

from wcdrive.plant import ChairParams, Plant

P = ChairParams(battery_capacity_ah=50.0)
D = 32 / 255
E = P.battery_full_voltage
CURRENT = D * E / (P.armature_resistance + 2 * D * D * P.battery_resistance)
TERMINAL = E - 2 * D * P.battery_resistance * CURRENT
DRAWN = 2 * D * CURRENT


def _stalled(params: ChairParams, use_kernel: bool = True) -> Plant:
    plant = Plant(params, use_kernel=use_kernel)
    for side in ("left", "right"):
        plant.set_wheel_locked(side)
    plant.set_drive(32, 1, 32, 1)
    return plant


def test_the_hand_figures() -> None:
    assert CURRENT == pytest.approx(10.652, abs=1e-3)
    assert TERMINAL == pytest.approx(25.466, abs=1e-3)
    assert DRAWN == pytest.approx(2.673, abs=1e-3)


@pytest.mark.parametrize("use_kernel", [True, False], ids=["kernel", "python"])
def test_under_load_the_voltage_sags_and_the_charge_runs_down(use_kernel: bool) -> None:
    """Stalled at duty 32 for 1 s (kernel 60 s): the current and the terminal voltage are
    the hand figures (the step's one-step lag settles at once: R_b 2 d^2 / R = 0.5 %),
    and the charge has fallen by I_b t / 180,000 C (the open-circuit voltage falls with
    it by 2 V per unit of charge: 1.8 mV over the minute, inside the tolerance)."""
    plant = _stalled(P, use_kernel)
    assert plant.battery == (E, 1.0)
    seconds = 60 if use_kernel else 1
    plant.advance(seconds * 1000, angles=False)
    volts, charge = plant.battery
    assert plant.left.current == pytest.approx(CURRENT, rel=1e-3)
    assert volts == pytest.approx(TERMINAL, abs=3e-3)
    assert 1.0 - charge == pytest.approx(DRAWN * seconds / (50.0 * 3600), rel=1e-3)


def test_the_reference_draws_as_the_kernel_does() -> None:
    kernel, reference = _stalled(P), _stalled(P, False)
    kernel.advance(2000, angles=False)
    reference.advance(2000, angles=False)
    assert kernel.battery[0] == pytest.approx(reference.battery[0], rel=1e-12)
    assert kernel.battery[1] == pytest.approx(reference.battery[1], rel=1e-12)


def test_a_flat_battery_gives_the_empty_voltage_and_the_motors_less() -> None:
    """At 10 % charge the open-circuit voltage is 23.8 V: the stall current falls in
    proportion, and the charge never goes below 0."""
    low = _stalled(ChairParams(battery_capacity_ah=50.0, battery_charge=0.1))
    low.advance(1000, angles=False)
    e = P.battery_empty_voltage + 0.1 * (P.battery_full_voltage - P.battery_empty_voltage)
    assert e == pytest.approx(23.8)
    expected = D * e / (P.armature_resistance + 2 * D * D * P.battery_resistance)
    assert low.left.current == pytest.approx(expected, rel=1e-3)
    empty = _stalled(ChairParams(battery_capacity_ah=1e-4, battery_charge=0.0))
    empty.advance(1000, angles=False)
    assert empty.battery[1] == 0.0


def test_without_a_capacity_the_supply_is_ideal() -> None:
    """The default chair: the driver sees supply_voltage, whatever it draws."""
    plant = _stalled(ChairParams())
    plant.advance(1000, angles=False)
    assert plant.battery == (24.0, 1.0)
    assert plant.left.current == pytest.approx(D * 24.0 / P.armature_resistance, rel=1e-9)
