"""wcdrive.testing: the plugin's fixtures (loaded through the pytest11 entry point, no
conftest) and the strategies, used as a downstream suite would."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings

from wcdrive.plant.encoders import EdgeTrain
from wcdrive.plant.faults import Fault
from wcdrive.protocol.codec import LineDecoder
from wcdrive.sim import runner
from wcdrive.sim.scenario import Scenario
from wcdrive.testing import SteppedChair, strategies
from wcdrive.testing.stepped import NEUTRAL_CONFIRM_S


def test_plugin_is_registered_by_entry_point(pytestconfig: pytest.Config) -> None:
    plugin = pytestconfig.pluginmanager.get_plugin("wcdrive")
    assert plugin is not None and plugin.__name__ == "wcdrive.testing.plugin"


def test_wc_port_drives_forward_and_stops_by_watchdog(wc_port: SteppedChair) -> None:
    wc_port.set_velocity(0.4, 0.0)
    for _ in range(10):
        wc_port.run(0.2)
        wc_port.set_velocity(0.4, 0.0)
    x, y, _ = wc_port.pose
    assert 0.3 < x < 1.2 and abs(y) < 0.1
    assert wc_port.feedback is not None and wc_port.feedback.vel_right > 1.0
    wc_port.run(2.0)                 # no command for 2 s: the 500 ms watchdog stops it
    assert "WATCHDOG" in wc_port.events
    assert wc_port.pwm == (0, 0)
    assert math.isclose(wc_port.time, NEUTRAL_CONFIRM_S + 4.0, abs_tol=1e-3)   # after its neutral


def test_wc_faulty_port_latches_the_encoder_fault(wc_faulty_port) -> None:
    chair = wc_faulty_port("encoder_cut", at=1.0, side="left")
    for _ in range(15):
        chair.set_velocity(0.4, 0.0)
        chair.run(0.2)
    assert any(e.startswith("FAULT,") for e in chair.events), list(chair.events)
    assert chair.pwm == (0, 0)
    healthy = wc_faulty_port()
    for _ in range(15):
        healthy.set_velocity(0.4, 0.0)
        healthy.run(0.2)
    assert not any(e.startswith("FAULT,") for e in healthy.events)


def test_wc_faulty_port_takes_fault_objects(wc_faulty_port) -> None:
    chair = wc_faulty_port(Fault(kind="reset", at=0.5))
    chair.run(1.0)
    assert chair.loop.boot_cycle > 0


def test_wc_chair_is_a_live_sim_chair(wc_chair) -> None:
    assert wc_chair.link_ok
    wc_chair.set_velocity(0.3, 0.0)
    assert wc_chair.url.startswith("sim://")


def test_wc_simavr_chair_runs_or_skips_with_reason(wc_simavr_chair) -> None:
    assert wc_simavr_chair.link_ok


@settings(max_examples=30, deadline=None)
@given(line=strategies.commands())
def test_commands_are_lines_the_decoder_survives(line: bytes) -> None:
    assert isinstance(line, bytes) and line
    chair = SteppedChair()
    chair.send(line)
    chair.run(0.06)                  # the firmware takes any line without crashing


@settings(max_examples=20, deadline=None)
@given(stream=strategies.byte_streams())
def test_byte_streams(stream: bytes) -> None:
    assert isinstance(stream, bytes)
    LineDecoder().feed(stream)


@settings(max_examples=20, deadline=None)
@given(train=strategies.encoder_traces(1.0))
def test_encoder_traces_are_edge_trains(train: EdgeTrain) -> None:
    assert isinstance(train, EdgeTrain)
    assert (train.times[1:] >= train.times[:-1]).all() and (train.times <= 1.0 + 1e-9).all()


@settings(max_examples=30, deadline=None)
@given(fault=strategies.faults(5.0))
def test_faults_are_valid(fault: Fault) -> None:
    assert 0 < fault.at <= 4.0


@settings(max_examples=5, deadline=None)
@given(sc=strategies.scenarios(max_segments=2))
def test_scenarios_run(sc: Scenario) -> None:
    result = runner.run(sc, dt=0.002)
    assert result.ticks >= int(sc.duration / 0.05) - 2


def test_simavr_fixture_skips_with_the_install_line_when_the_toolchain_is_missing(monkeypatch) -> None:
    from wcdrive.boards.simavr import build
    from wcdrive.testing import plugin

    def missing() -> None:
        raise build.BuildError("avr-gcc is missing: apt-get install gcc-avr avr-libc")

    monkeypatch.setattr(build, "firmware_elf", missing)
    reason = plugin.simavr_missing()
    assert reason is not None and "apt-get install gcc-avr" in reason and reason.startswith("simavr://")
    with pytest.raises(pytest.skip.Exception, match="apt-get install gcc-avr"):
        next(plugin.wc_simavr_chair.__wrapped__())  # type: ignore[attr-defined]
