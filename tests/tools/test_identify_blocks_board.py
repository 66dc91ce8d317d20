"""``ident_blocks`` on the simulated board with its drive wheels off the ground: a chair
file with ``friction = 0`` stands for blocks (no tyre force; the wheel spins up to its
motor's no-load speed, ``tests/plant/test_grip.py``). The board in the loop (the port,
its PID and ramps, the lines it sends) drives a chair whose wheel figures the fit is
not told, and ``bench identify`` must find each within 5 %.

The host paces the scenario by the wall clock. At 10x the board keeps up with it on a
loaded 2-core machine. At 50x, with the rest of the suite running beside it, the
wheel-inertia fit once came out 5.1 % off."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from wcdrive.plant.identify import identify, with_motor_constant
from wcdrive.plant.params import ChairParams, chair_toml
from wcdrive.tools.bench import run_scenario
from wcdrive.tools.identify import run_of

#: The secret wheel figures, as factors on the defaults.
SECRET = {"motor_constant": 1.3, "wheel_inertia": 1.28, "current_limit": 0.77}


def test_the_blocks_fit_finds_the_wheel_figures_of_a_board_driven_chair(tmp_path: Path) -> None:
    d = ChairParams()
    secret = with_motor_constant(
        dataclasses.replace(d, friction=0.0, wheel_inertia=d.wheel_inertia * SECRET["wheel_inertia"],
                            current_limit=d.current_limit * SECRET["current_limit"]),
        d.motor_constant * SECRET["motor_constant"])
    chair = tmp_path / "blocks.toml"
    chair.write_text(chair_toml({name: getattr(secret, name) for name in
                                 ("friction", "top_wheel_speed", "wheel_inertia", "current_limit")}))
    recording = run_scenario("ident_blocks", f"sim://?chair={chair}&speed=10", speed=10.0)
    run = run_of(recording, blocks=True)
    assert run.blocks and 40.0 <= run.duration <= 60.0
    fit = identify([run])
    assert not fit.unpinned, fit.report()
    for name in SECRET:
        assert fit.values[name] == pytest.approx(getattr(secret, name), rel=0.05), (name, fit.report())
