"""A scenario's ``host_offset_s``: every byte of its host that much later, so a sweep can
draw the host's phase against the board's 50 ms ticks (``benchmarks/envelope.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from wcdrive.sim import runner, scenario
from wcdrive.sim.scenario import MOTION_START_S, NEUTRAL_AT_S, ScenarioError

BASE = ('name = "x"\nsettle_s = 0.5\n[params]\nmax_accel = 4.0\n'
        '[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 1.0\n')


def _load(tmp_path: Path, head: str) -> scenario.Scenario:
    path = tmp_path / "x.toml"
    path.write_text(head + BASE)
    return scenario.load(str(path))


def test_the_offset_moves_every_byte_and_the_figures_anchored_on_them(tmp_path: Path) -> None:
    plain, late = _load(tmp_path, ""), _load(tmp_path, "host_offset_s = 0.031\n")
    shifted = [round(t - 0.031, 9) for t, _ in late.host_commands()]
    assert shifted == [round(t, 9) for t, _ in plain.host_commands()]
    assert [d for _, d in late.host_commands()] == [d for _, d in plain.host_commands()]
    assert late.host_commands()[1][0] == pytest.approx(NEUTRAL_AT_S + 0.031)
    assert late.segments_start == pytest.approx(MOTION_START_S + 0.031)
    assert late.duration == pytest.approx(plain.duration + 0.031)


def test_the_chair_moves_that_much_later(tmp_path: Path) -> None:
    """40 ms later, the chair's first 5 cm/s comes 0 to 100 ms later (the board starts
    on its own ticks: the commands' phase against them moves)."""
    runs = [runner.run(_load(tmp_path, f"host_offset_s = {offset}\n")) for offset in (0.0, 0.04)]
    starts = [next(t for t, v in zip(r.truth.step_time, r.truth.step_speed, strict=True) if v > 0.05)
              for r in runs]
    assert 0.0 < starts[1] - starts[0] < 0.1, starts


@pytest.mark.parametrize("value", ["-0.01", "1.0", "true", '"0.02"'])
def test_an_offset_out_of_range_is_a_scenario_error(tmp_path: Path, value: str) -> None:
    with pytest.raises(ScenarioError, match="host_offset_s"):
        _load(tmp_path, f"host_offset_s = {value}\n")
