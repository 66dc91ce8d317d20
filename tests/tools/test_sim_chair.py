"""``wcdrive sim --chair chair.toml``: the simulated chair takes the chair file's
``[chair]`` table; a scenario's own ``[chair]`` keys (a wet patch, say) win over it."""

from __future__ import annotations

from pathlib import Path

import pytest

from wcdrive.plant.params import ChairParams
from wcdrive.sim import runner
from wcdrive.sim.scenario import Scenario
from wcdrive.tools.cli import main as wcdrive_main


def test_sim_runs_the_scenario_on_the_chair_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    chair = tmp_path / "chair.toml"
    chair.write_text("[chair]\nchair_mass = 95.0\nfriction = 0.5\n")
    scenario = tmp_path / "wet.toml"
    scenario.write_text('name = "wet"\n[chair]\nfriction = 0.2\n[[segment]]\nstop = true\nduration = 0.5\n')
    seen: list[ChairParams] = []

    def run(sc: Scenario, **_: object) -> object:
        seen.append(sc.params())
        raise SystemExit(0)                    # the run itself is the runner's business

    monkeypatch.setattr(runner, "run", run)
    with pytest.raises(SystemExit):
        wcdrive_main(["sim", str(scenario), "--chair", str(chair), "--no-plots"])
    assert seen[0].chair_mass == 95.0 and seen[0].friction == 0.2
    assert wcdrive_main(["sim", str(scenario), "--chair", str(tmp_path / "none.toml")]) == 2
    assert "cannot read chair file" in capsys.readouterr().err
