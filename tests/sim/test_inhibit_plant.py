"""The inhibit inputs with the chair in the loop (docs/safety.md, "Inhibit inputs"):
the bundled scenarios ``charger_inhibit`` (input 1 stops the chair along its normal ramp
and latches) and ``seat_raised_speed_cap`` (input 2 caps the speed; lowered, the chair
stops and waits for neutral) keep their ``[expect]`` contracts on the compiled firmware
in simavr, its pins driven by the scenario's ``[[input]]`` timeline, with 0 differences
from the port (the port's runs are in tests/sim/test_scenario_contracts.py). And the
``[[input]]`` table is checked as it is read."""

from __future__ import annotations

from pathlib import Path

import pytest

from wcdrive.boards.inhibits import InhibitChange, active_bits
from wcdrive.sim import contract, runner, scenario
from wcdrive.sim.scenario import ScenarioError

pytestmark = pytest.mark.simavr


@pytest.mark.parametrize("name", ["charger_inhibit", "seat_raised_speed_cap"])
def test_the_inhibit_scenarios_keep_their_contracts_on_simavr(name: str) -> None:
    loaded = scenario.load(name)
    result = runner.run(loaded, backend="simavr")
    assert contract.check(loaded, result) == []
    assert result.firmware_differences == 0
    kinds = {line for _, line in result.link.events}
    assert any(k.startswith("EVT:INHIBIT,") for k in kinds)


def test_the_timeline_reads_as_the_pins_do() -> None:
    changes = [InhibitChange(1.0, 1, True), InhibitChange(0.5, 2, True), InhibitChange(2.0, 1, False)]
    assert [active_bits(changes, t) for t in (0.0, 0.5, 1.0, 1.5, 2.0)] == [0, 2, 3, 3, 2]


BASE = 'name = "x"\n[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 2.0\n'


@pytest.mark.parametrize(("table", "says"), [
    ('[[input]]\nat = 1.0\ninput = "door"\n', "no inhibit input 'door'"),
    ('[[input]]\nat = 9.0\ninput = "seat"\n', "at must be a time within the scenario"),
    ('[[input]]\nat = 1.0\ninput = "seat"\nactive = 1\n', "active must be true or false"),
    ('[[input]]\nat = 1.0\ninput = "seat"\nlevel = 0\n', "unknown keys level"),
    ('input = 3\n', "inputs are [[input]] tables"),
])
def test_a_malformed_input_table_is_a_scenario_error(tmp_path: Path, table: str, says: str) -> None:
    path = tmp_path / "x.toml"
    path.write_text(table + BASE if not table.startswith("[[") else BASE + table)
    with pytest.raises(ScenarioError, match=says.replace("[", r"\[").replace("]", r"\]")):
        scenario.load(str(path))


def test_an_input_table_reads_by_name_or_number(tmp_path: Path) -> None:
    path = tmp_path / "x.toml"
    path.write_text(BASE + '[[input]]\nat = 1.5\ninput = 2\nactive = false\n[[input]]\nat = 0.5\n'
                    'input = "charger"\n')
    assert scenario.load(str(path)).inhibits == (InhibitChange(0.5, 1, True), InhibitChange(1.5, 2, False))
