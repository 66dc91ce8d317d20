"""Fault injection ("Fault injection, for users and for tests"): scenario
``[[fault]]`` entries, what each kind does to the plant and to the firmware's inputs on
both backends, the fault figures of ``wcdrive sim --json``, and the issue's safety
bounds ("Done when") on every bundled fault scenario, on the port and on the firmware
in simavr (whose runs must also show 0 differences from the port)."""

from __future__ import annotations

import dataclasses
import importlib.util
import io
import json
import math
import sys
from contextlib import redirect_stdout
from functools import cache
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.support.depth import cases
from wcdrive.avr.timer0 import F_CPU
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.port_loop import FIRST_OVERFLOW_CYCLE, PortLoop
from wcdrive.firmware.quadrature import QuadratureDecoder
from wcdrive.plant import Plant, encoder_counts
from wcdrive.plant.encoders import state_for_count
from wcdrive.plant.faults import EncoderWire, Fault, swap_ab
from wcdrive.protocol.codec import encode_cmdvel
from wcdrive.sim import runner, safety, scenario
from wcdrive.sim.result import BoardLog, GroundTruth, Odometry
from wcdrive.sim.scenario import Scenario, ScenarioError, Segment
from wcdrive.tools.cli import main as wcdrive_main

FAULT_SCENARIOS = [p.stem for p in scenario.bundled() if p.stem.startswith("fault_")]
BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))


@cache
def _run(name: str, backend: str) -> runner.SimResult:
    """A bundled scenario's run, once per test process."""
    return runner.run(scenario.load(name), backend=backend)


def _write(tmp_path: Path, fault: str, segments: str = "[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 3\n",
           extra: str = "") -> str:
    path = tmp_path / "f.toml"
    path.write_text(f"settle_s = 0.0\n{extra}\n{segments}\n[[fault]]\n{fault}\n")
    return str(path)


# ---- the scenario format ------------------------------------------------------------
def test_faults_parse(tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_text('[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 4\n'
                    '[[fault]]\nat = 2.0\nkind = "encoder_cut"\nside = "left"\nduration = 1\n'
                    '[[fault]]\nat = 1\nkind = "encoder_noise"\nside = "both"\nrate_hz = 200000\n'
                    '[[fault]]\nat = 3.5\nkind = "reset"\n')
    sc = scenario.load(str(path))
    assert sc.faults == (Fault("encoder_cut", 2.0, "left", 1.0),
                         Fault("encoder_noise", 1.0, "both", None, 200000.0), Fault("reset", 3.5))
    assert sc.faults[0].end == 3.0 and math.isinf(sc.faults[1].end)
    assert sc.faults[1].sides() == ("left", "right") and sc.faults[2].sides() == ()


@pytest.mark.parametrize(("fault", "message"), [
    ('at = 1\nkind = "encoder_snapped"\nside = "left"', r"fault 1: kind must be one of encoder_cut"),
    ('kind = "encoder_cut"\nside = "left"', r"fault 1: at \(s from the start\) is missing"),
    ('at = "soon"\nkind = "reset"', r"fault 1: at \(s from the start\) is missing or not a number"),
    ('at = 0\nkind = "reset"', r"fault 1: at must be a positive time"),
    ('at = 9\nkind = "reset"', r"fault 1: at = 9.0 s is not within the scenario \(3.000 s\)"),
    ('at = 1\nkind = "encoder_cut"', r'fault 1: encoder_cut needs side = "left", "right" or "both"'),
    ('at = 1\nkind = "wheel_locked"\nside = "middle"', r"fault 1: wheel_locked needs side .*not 'middle'"),
    ('at = 1\nkind = "link_cut"\nside = "left"', r"fault 1: link_cut takes no side"),
    ('at = 1\nkind = "motor_dead"\nside = "left"\nduration = -2', r"fault 1: duration must be a positive"),
    ('at = 1\nkind = "motor_dead"\nside = "left"\nduration = "long"', r"fault 1: duration must be a number"),
    ('at = 1\nkind = "reset"\nduration = 1', r"fault 1: reset is instantaneous"),
    ('at = 1\nkind = "encoder_noise"\nside = "left"', r"fault 1: encoder_noise needs rate_hz"),
    ('at = 1\nkind = "encoder_noise"\nside = "left"\nrate_hz = 1e9', r"fault 1: encoder_noise needs rate_hz"),
    ('at = 1\nkind = "encoder_cut"\nside = "left"\nrate_hz = 100',
     r"fault 1: rate_hz is for encoder_noise only"),
    ('at = 1\nkind = "reset"\nwhen = 2', r"fault 1: unknown keys when \(a fault takes at, kind, side"),
])
def test_fault_errors_are_clear(tmp_path: Path, fault: str, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        scenario.load(_write(tmp_path, fault))


def test_second_fault_is_named(tmp_path: Path) -> None:
    path = _write(tmp_path, 'at = 1\nkind = "reset"\n[[fault]]\nat = 2\nkind = "reset"\nside = "both"')
    with pytest.raises(ScenarioError, match="fault 2: reset takes no side"):
        scenario.load(path)


def test_board_params_are_sent_first_and_checked(tmp_path: Path) -> None:
    sc = scenario.load(_write(tmp_path, 'at = 1\nkind = "reset"', extra="[params]\nwatchdog_ms = 1000\n"))
    assert sc.board_params == {"watchdog_ms": 1000.0}
    assert sc.host_commands()[0] == (0.005, b"set:watchdog_ms=1000\n")
    with pytest.raises(ScenarioError, match=r"\[params\] watchdog_ms: .*outside"):
        scenario.load(_write(tmp_path, 'at = 1\nkind = "reset"', extra="[params]\nwatchdog_ms = 99999\n"))
    with pytest.raises(ScenarioError, match=r"\[params\] speed: unknown parameter"):
        scenario.load(_write(tmp_path, 'at = 1\nkind = "reset"', extra="[params]\nspeed = 1\n"))


def test_every_bundled_fault_kind_has_a_scenario() -> None:
    kinds = {f.kind for name in FAULT_SCENARIOS for f in scenario.load(name).faults}
    assert kinds == {"encoder_cut", "encoder_reversed", "encoder_noise", "wheel_locked", "motor_dead",
                     "brake_open", "brake_short", "reset", "link_cut"}
    for name in FAULT_SCENARIOS:
        assert name == "fault_silence" or scenario.load(name).faults


# ---- the wire between an encoder and the board ---------------------------------------
def _forward_train(counts: int, cycles_per_count: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    ticks = np.arange(1, counts + 1, dtype=np.int64) * cycles_per_count
    return ticks, np.asarray(state_for_count(np.arange(1, counts + 1)), dtype=np.int64)


def _decode(ticks: np.ndarray, states: np.ndarray) -> QuadratureDecoder:
    d = QuadratureDecoder()
    d.bulk(states)
    return d


def test_a_cut_wire_freezes_then_shows_the_encoder_again() -> None:
    ticks, states = _forward_train(100)
    wire = EncoderWire([Fault("encoder_cut", 30_500 / F_CPU, "left", 42_000 / F_CPU)], "left", F_CPU)
    out_t, out_s = wire.transform(0, 100_000, ticks, states)
    assert not np.any((out_t >= 30_500) & (out_t < 72_500))            # nothing while cut
    assert out_t[np.searchsorted(out_t, 72_500)] == 72_500                # reconnected: the true state
    assert out_s[-1] == states[-1] and wire.state == states[-1]
    d = _decode(out_t, out_s)
    # 30 counts before the cut, the jump at reconnection (30 -> 72, two steps on in the
    # cycle of four: illegal), then 28 more: from where the cut left it, plus the motion.
    assert d.count == 30 + 28 and d.illegal == 1


def test_a_reversed_wire_counts_backwards() -> None:
    ticks, states = _forward_train(100)
    at = 40_500
    wire = EncoderWire([Fault("encoder_reversed", at / F_CPU, "right")], "right", F_CPU)
    out_t, out_s = wire.transform(0, 100_000, ticks, states)
    after = out_t > at
    assert np.array_equal(out_s[after], swap_ab(states[ticks > at]))
    d = QuadratureDecoder()
    d.bulk(out_s[out_t <= at])
    c_at = d.count
    d.bulk(out_s[after])
    assert c_at == 40 and d.count == 2 * c_at - 100               # c(t) = 2 c(at) - true(t)


def test_a_noisy_wire_chatters_on_a_at_its_rate() -> None:
    ticks, states = _forward_train(100)
    rate = 400_000.0                                            # one toggle every 40 cycles
    wire = EncoderWire([Fault("encoder_noise", 20_000 / F_CPU, "left", 40_000 / F_CPU, rate)], "left", F_CPU)
    out = [wire.transform(lo, lo + 16_000, ticks[(ticks > lo) & (ticks <= lo + 16_000)],
                          states[(ticks > lo) & (ticks <= lo + 16_000)]) for lo in range(0, 112_000, 16_000)]
    out_t = np.concatenate([o[0] for o in out])
    out_s = np.concatenate([o[1] for o in out])
    assert np.all(np.diff(out_t) >= 0)
    noise = (out_t >= 20_000) & (out_t < 60_000)
    # B is the encoder's own; A toggles at 20,040, 20,080, ... 59,960 (999 times) on top
    # of the 40 true edges, and A is itself again from the end (an edge at 60,000).
    assert np.count_nonzero(noise) == 999 + 40
    assert out_t.size == 100 + 999 + 1
    b = out_s & 1
    true_b = np.asarray(state_for_count(np.arange(0, 101)))[np.searchsorted(ticks, out_t, "right")] & 1
    same_tick = out_t == 60_000           # the end of the noise, then the true edge at that tick
    assert np.array_equal(b[~same_tick], true_b[~same_tick])
    assert out_s[-1] == states[-1]                              # clean again afterwards
    # Through the ISR model: illegal-free chatter counts back and forth, and the storm
    # guard masks the encoder within the first Timer0 window.
    d = QuadratureDecoder()
    from wcdrive.avr.timer0 import storm_window
    d.edges_in_windows(out_s, storm_window(out_t + 30 * F_CPU // 1000))
    assert d.storm


# ---- the port backend's inputs -------------------------------------------------------
#: A neutral command at 5 ms, as every host sends one: the board drives only once one
#: stood (docs/safety.md, "Neutral before motion"); the drive from 140 ms.
NEUTRAL = encode_cmdvel(0.0, 0.0)
DRIVE_FROM_S = 0.14


def _port(faults: list[Fault], seconds: float, speed: float = 0.5) -> tuple[PortLoop, list[tuple]]:
    plant = Plant()
    loop = PortLoop(plant, faults=faults)
    loop.send(NEUTRAL, at=round(0.005 * F_CPU))
    for k in range(int(seconds * 10)):
        loop.send(encode_cmdvel(speed, 0.0), at=round((DRIVE_FROM_S + 0.1 * k) * F_CPU))
    rows: list[tuple] = []

    def on_tick(t: float) -> None:
        s = loop.fw.state
        true = encoder_counts(plant.left.angle, plant.right.angle)
        rows.append((t, s.encTickL, s.encTickR, *true, s.illTickL, s.illTickR))

    loop.run_until(round(seconds * F_CPU), on_tick)
    return loop, rows


def test_port_cut_encoder_count_freezes_and_resumes() -> None:
    _, rows = _port([Fault("encoder_cut", 1.0, "right", 0.3)], 2.0)
    a = np.array(rows)
    cut = (a[:, 0] > 1.0) & (a[:, 0] < 1.3)
    frozen = a[cut, 2]
    assert np.all(frozen == frozen[0]) and np.ptp(a[cut, 4]) > 100      # the wheel turned on
    before = a[a[:, 0] < 1.0][-1]
    # ideal count at the cut (ticks latch at overflows, the cut is at 1.0 s exactly)
    assert before[2] <= frozen[0] <= before[2] + 300
    after = a[:, 0] > 1.3
    offset = a[after, 2] - a[after, 4]
    assert np.all(offset == offset[0]) and offset[0] < -100         # resumed: frozen + true motion
    assert np.all(a[:, 1] == a[:, 3])                               # the other side untouched


def test_port_reversed_encoder_runs_backwards() -> None:
    _, rows = _port([Fault("encoder_reversed", 1.0, "left", 0.1)], 1.5)
    a = np.array(rows)
    fault = (a[:, 0] > 1.0) & (a[:, 0] < 1.1)
    # c(t) = 2 c(at) - true(t): count plus true count stays 2 c(at), c(at) the true count
    # at 1.0 s, between those of the ticks around it
    sums = a[fault, 1] + a[fault, 3]
    assert np.all(sums == sums[0])
    before, after = a[a[:, 0] < 1.0][-1, 3], a[fault][0, 3]
    assert min(before, after) <= sums[0] / 2 <= max(before, after)
    assert np.all(np.diff(a[fault, 1]) > 0) and np.all(np.diff(a[fault, 3]) < 0)
    later = a[:, 0] > 1.1
    offset = a[later, 1] - a[later, 3]                             # then it follows the wheel again
    assert np.all(offset == offset[0])


def test_port_noise_masks_the_isr_until_reset() -> None:
    plant = Plant()
    loop = PortLoop(plant, faults=[Fault("encoder_noise", 1.0, "left", 0.2, 200_000.0)])
    loop.send(NEUTRAL, at=round(0.005 * F_CPU))
    for k in range(20):
        loop.send(encode_cmdvel(0.5, 0.0), at=round((DRIVE_FROM_S + 0.1 * k) * F_CPU))
    loop.run_until(round(1.05 * F_CPU))
    assert loop._encoders["left"].decoder.storm and loop.fw.state.stormL
    assert not loop._encoders["right"].decoder.storm
    frozen = loop.encoder_counts()[0]
    loop.run_until(round(3.0 * F_CPU))                             # the fault stopped the chair
    assert loop.encoder_counts()[0] == frozen and loop._encoders["left"].edge_mode
    loop.send(b"reset\n")
    loop.run_until(round(3.1 * F_CPU))
    assert not loop._encoders["left"].decoder.storm and not loop._encoders["left"].edge_mode
    loop.send(NEUTRAL, at=round(3.1 * F_CPU))               # released: neutral before motion
    for k in range(10):
        loop.send(encode_cmdvel(0.3, 0.0), at=round((3.25 + 0.1 * k) * F_CPU))
    loop.run_until(round(4.15 * F_CPU))
    assert loop.encoder_counts()[0] < frozen - 500                  # counting again


def test_port_reset_restarts_the_board() -> None:
    plant = Plant()
    loop = PortLoop(plant)
    loop.send(NEUTRAL, at=round(0.005 * F_CPU))
    for k in range(15):
        loop.send(encode_cmdvel(0.5, 0.0), at=round((DRIVE_FROM_S + 0.1 * k) * F_CPU))
    loop.run_until(round(1.0 * F_CPU))
    assert loop.fw.state.pwmL > 0
    loop.take_output()
    loop.reset()
    assert loop.plant.s.volts[0] == 0.0 and loop.plant.s.volts[1] == 0.0   # unpowered at once
    # the BOOT line, then the EEPROM parameters' boot event (blank: nothing was saved)
    assert loop.take_output() == [(round(1.0 * F_CPU),
                                   b"BOOT:final_control,EXTERNAL\r\nEVT:PARAMS_DEFAULT,blank\r\n")]
    assert loop.encoder_counts() == (0, 0) and loop.fw.state.tickCount == 0
    ticks: list[int] = []
    loop.run_until(round(1.2 * F_CPU), lambda t: ticks.append(loop.last_tick_cycle or 0))
    # the first tick after the reset: millis() 50 from Timer0's first overflow, as at power-on
    power_on = PortLoop(Plant())
    first: list[int] = []
    power_on.run_until(round(0.2 * F_CPU), lambda t: first.append(power_on.last_tick_cycle or 0))
    assert ticks[0] - round(1.0 * F_CPU) == first[0] > FIRST_OVERFLOW_CYCLE


def test_port_reset_fault_is_scheduled() -> None:
    loop, _ = _port([Fault("reset", 0.8)], 1.0)
    assert any(c == round(0.8 * F_CPU) and out.startswith(b"BOOT:") for c, out in loop.output)


# ---- the plant faults -----------------------------------------------------------------
@pytest.mark.parametrize("use_kernel", [True, False])
def test_locked_wheel_does_not_turn(use_kernel: bool) -> None:
    p = Plant(use_kernel=use_kernel)
    p.set_drive(200, 1, 200, 1)
    p.advance(1000)
    p.set_wheel_locked("left")
    angle = p.left.angle
    p.advance(1000)
    assert p.left.speed == 0.0 and p.left.angle == angle and p.wheel_locked("left")
    assert abs(p.left.slip) > 0.0 or abs(p.axle_velocity()[0]) < 1e-3       # the tyre slides
    assert p.right.speed > 1.0                                               # it pivots on the locked wheel
    assert p.left.current == pytest.approx(p.p.current_limit)               # a stalled motor
    p.set_wheel_locked("left", False)
    p.advance(500)
    assert p.left.speed > 1.0


@pytest.mark.parametrize("use_kernel", [True, False])
def test_dead_motor_gives_no_torque_and_no_braking(use_kernel: bool) -> None:
    dead, alive = Plant(use_kernel=use_kernel), Plant(use_kernel=use_kernel)
    for p in (dead, alive):
        p.set_motor_dead("left")
        p.set_drive(255, 1, 0, 1)
        p.advance(500)
    assert dead.left.speed == 0.0 and dead.left.current == 0.0        # full duty, no torque
    for p in (dead, alive):
        p.set_motor_dead("left", False)
        p.set_drive(200, 1, 200, 1)
        p.advance(2000)
    speed = dead.left.speed
    dead.set_motor_dead("left")
    for p in (dead, alive):
        p.set_drive(0, 1, 0, 1)                  # a live motor at duty 0 brakes by back-EMF
        p.advance(300)
    assert dead.left.current == 0.0
    assert dead.left.speed > alive.left.speed + 1.0 and dead.left.speed < speed


def test_plant_faults_agree_between_c_and_python() -> None:
    fast, ref = Plant(), Plant(use_kernel=False)
    for p in (fast, ref):
        p.start_motion_log()
        p.set_drive(180, 1, 120, 1)
        p.advance(400)
        p.set_motor_dead("right")
        p.advance(300)
        p.set_wheel_locked("left")
        p.advance(300)
    assert fast.pose == pytest.approx(ref.pose, abs=1e-12)
    assert np.allclose(fast.take_motion_log(), ref.take_motion_log(), atol=1e-12, rtol=0)


# ---- the fault figures -----------------------------------------------------------------
def _synthetic(speed: list[float], volts: list[float], fault_at: float, ticks=(0,)) -> runner.SimResult:
    n = len(speed)
    z = np.zeros((1, 2))
    return runner.SimResult(
        scenario="x", backend="port", duration=n * 0.1, wall_time=1.0,
        truth=GroundTruth(np.zeros((1, 3)), z, z, step_time=0.1 * np.arange(1, n + 1),
                          step_speed=np.array(speed),
                          step_contact_speed=np.stack((np.array(speed), 0.5 * np.array(speed)), axis=1),
                          step_volts=np.stack((np.array(volts), np.zeros(n)), axis=1)),
        board=BoardLog(np.zeros(1), z, z, z, z, tick_cycles=np.array(ticks, dtype=np.int64)),
        odometry=Odometry(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3))), fault_at=fault_at)


def test_fault_figures_from_ground_truth() -> None:
    r = _synthetic([1.0, 1.0, 2.0, 1.0, 0.5, 0.005, 0.02, 0.0, 0.0, 0.0],
                   [5.0, 5.0, 5.0, -3.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], fault_at=0.2,
                   ticks=(0, round(0.05 * F_CPU), round(0.3 * F_CPU)))
    m = r.fault_metrics()
    assert m["fault_at_s"] == 0.2
    assert m["pwm_zero_after_fault_s"] == pytest.approx(0.6 - 0.2)     # the step from 0.6 s on
    assert m["standstill_after_fault_s"] == pytest.approx(0.7 - 0.2)   # below 0.01 m/s from 0.7 s on
    assert m["travel_after_fault_m"] == pytest.approx((2.0 + 1.0 + 0.5 + 0.005 + 0.02) * 0.1)
    assert m["peak_speed_after_fault_mps"] == 2.0
    assert m["max_tick_gap_ms"] == pytest.approx(700.0)               # the last tick to the end
    never = _synthetic([1.0] * 5, [5.0] * 5, fault_at=0.1).fault_metrics()
    assert never["pwm_zero_after_fault_s"] is None and never["standstill_after_fault_s"] is None
    none = _synthetic([1.0] * 5, [5.0] * 5, fault_at=None).fault_metrics()   # type: ignore[arg-type]
    assert none["fault_at_s"] is None and none["travel_after_fault_m"] is None


def test_link_cut_drops_bytes_mid_line() -> None:
    data = encode_cmdvel(0.5, 0.0)
    start = round(1.0 * F_CPU)
    cut = Fault("link_cut", (start + 5 * UART_BYTE_CYCLES + 10) / F_CPU,
                duration=4 * UART_BYTE_CYCLES / F_CPU)
    wire = runner.wire_schedule([(start, data), (start + 100, data)], (cut,))
    # byte 5 starts before the cut, bytes 6..9 within it, byte 10 on after it
    assert wire.runs[0] == (start, data[:6])
    assert wire.runs[1] == (start + 10 * UART_BYTE_CYCLES, data[10:])
    assert wire.runs[2][0] == start + len(data) * UART_BYTE_CYCLES     # the next one queued behind
    byte = UART_BYTE_CYCLES / F_CPU
    sc = Scenario("cut", "", (Segment("cmdvel", (0.5, 0.0), 2.0),), settle_s=0.0,
                  faults=(Fault("link_cut", 1.17 + 5.5 * byte),))
    commands = [(round(t * F_CPU), d) for t, d in sc.host_commands() if t < sc.duration]
    wire = runner.wire_schedule(commands, sc.faults)
    # the command sent at 1.17 s (the neutral at 8 ms, then 10 Hz from 0.17 s) loses its
    # bytes from the 7th on; the 6th is the last the board receives
    assert runner.fault_time(sc, wire) == pytest.approx(1.17 + 6 * byte, abs=1e-6)
    assert sum(len(d) for _, d in wire.runs) == len(NEUTRAL) + 10 * len(data) + 6


def test_silence_counts_from_the_last_byte() -> None:
    sc = scenario.load("fault_silence")
    commands = [(round(t * F_CPU), d) for t, d in sc.host_commands() if t < sc.duration]
    at = runner.fault_time(sc, runner.wire_schedule(commands))
    assert at == pytest.approx(3.57 + len(commands[-1][1]) * UART_BYTE_CYCLES / F_CPU, abs=1e-6)


def test_sim_json_reports_the_fault_figures(tmp_path: Path) -> None:
    path = _write(tmp_path, 'at = 1.0\nkind = "encoder_cut"\nside = "both"',
                  segments="[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 2.5\n")
    out = io.StringIO()
    with redirect_stdout(out):
        assert wcdrive_main(["sim", path, "--json", "--no-plots"]) == 0
    [m] = json.loads(out.getvalue())
    for key in ("events", "max_tick_gap_ms", "fault_at_s", "pwm_zero_after_fault_s",
                "standstill_after_fault_s", "travel_after_fault_m", "peak_speed_after_fault_mps"):
        assert key in m
    assert m["fault_at_s"] == 1.0 and 49.0 < m["max_tick_gap_ms"] < 52.0
    assert all(isinstance(t, float) and line.startswith("EVT:") for t, line in m["events"])
    assert m["travel_after_fault_m"] > 0 and m["peak_speed_after_fault_mps"] > 0
    out = io.StringIO()
    with redirect_stdout(out):
        assert wcdrive_main(["sim", "spin_360", "--json", "--no-plots"]) == 0
    [m] = json.loads(out.getvalue())
    assert m["fault_at_s"] is None and m["standstill_after_fault_s"] is None
    assert m["pwm_zero_after_fault_s"] is None
    # the boot's EEPROM event, then the silence after the last stop
    assert [line for _, line in m["events"]] == ["EVT:PARAMS_DEFAULT,blank", "EVT:WATCHDOG"]


def test_sim_table_names_the_fault(tmp_path: Path) -> None:
    path = _write(tmp_path, 'at = 1.0\nkind = "wheel_locked"\nside = "right"',
                  segments="[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 2.0\n")
    out = io.StringIO()
    with redirect_stdout(out):
        wcdrive_main(["sim", path, "--no-plots"])
    assert "fault: wheel_locked right at 1 s" in out.getvalue()
    assert "after the fault (1.000 s): PWM 0 after" in out.getvalue()


# ---- each kind on both backends: inputs and ground truth ------------------------------
def _after(r: runner.SimResult, t: float) -> np.ndarray:
    return r.board.tick_time > t


@pytest.mark.parametrize("backend", BACKENDS)
def test_cut_encoder_count_freezes_on_both_backends(backend: str) -> None:
    r = _run("fault_encoder_cut_both", backend)
    counts = r.board.counts[r.board.tick_time > 1.5 + 0.002]
    assert np.all(counts == counts[0])
    assert np.ptp(r.board.counts[(r.board.tick_time > 1.0) & (r.board.tick_time < 1.5)], axis=0).min() > 500


@pytest.mark.parametrize("backend", BACKENDS)
def test_reversed_encoder_counts_against_the_wheel_on_both_backends(backend: str) -> None:
    r = _run("fault_encoder_reversed", backend)
    window = (r.board.tick_time > 1.51) & (r.board.tick_time < 1.62)
    # the left encoder counts down going forward; reversed, it counts up
    assert np.all(r.truth.wheel_speed[window, 0] > 1.0)
    assert np.all(np.diff(r.board.counts[window, 0]) > 0)
    before = (r.board.tick_time > 1.2) & (r.board.tick_time < 1.5)
    assert np.all(np.diff(r.board.counts[before, 0]) < 0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_locked_wheel_stands_still_on_both_backends(backend: str) -> None:
    r = _run("fault_wheel_locked", backend)
    assert np.all(r.truth.wheel_speed[_after(r, 1.51), 0] == 0.0)
    # up to speed by then (the drive from 0.17 s, after the neutral command)
    assert np.all(r.truth.wheel_speed[(r.board.tick_time > 1.15) & (r.board.tick_time < 1.5), 0] > 2.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dead_motor_on_both_backends(backend: str) -> None:
    r = _run("fault_motor_dead", backend)
    before, after = np.searchsorted(r.truth.step_time, [1.45, 2.0])
    left, right = r.truth.step_contact_speed[before]
    assert abs(left - right) < 0.02
    # the left motor drives no more: its side falls behind whatever duty it gets
    left, right = r.truth.step_contact_speed[after]
    assert left < right - 0.02 and r.truth.step_volts[after, 0] > r.truth.step_volts[before, 0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_noise_reaches_the_isr_on_both_backends(backend: str) -> None:
    r = _run("fault_encoder_noise_100k", backend)
    assert any(line == "EVT:FAULT,ENC_IMPLAUSIBLE_L" for _, line in r.link.events)
    assert not any(line == "EVT:FAULT,ENC_IMPLAUSIBLE_R" for _, line in r.link.events)


@pytest.mark.parametrize("backend", BACKENDS)
def test_reset_reboots_the_board_on_both_backends(backend: str) -> None:
    r = _run("fault_reset", backend)
    boots = [line for _, line in r.link.boots]
    assert boots == ["BOOT:final_control,POWER_ON", "BOOT:final_control,EXTERNAL"]
    assert 1.5 <= r.link.boots[1][0] < 1.505                     # sent once setup() has run
    i = np.searchsorted(r.truth.step_time, 1.5 + 1e-9)
    assert np.all(r.truth.step_volts[i:i + 40] == 0.0) and np.any(r.truth.step_volts[i - 5:i] != 0.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_link_cut_silences_the_host_on_both_backends(backend: str) -> None:
    r = _run("fault_link_cut", backend)
    assert r.fault_at is not None and 3.67 < r.fault_at < 3.671 + 2 * UART_BYTE_CYCLES / F_CPU
    assert any(line == "EVT:WATCHDOG" for _, line in r.link.events)


# ---- the safety bounds ----------------------------------------------------------
#: The fault scenarios the fast depth also runs on simavr (the thorough one runs them
#: all): every kind, the cut on one side, on both and at speed, the noise at the lowest
#: rate on one side, the silence. Left for the thorough depth: the rest of the noise's
#: rate x side grid (fault_encoder_noise is its 200k left, 500k on both the highest) and
#: the fast cut on one side.
SAFETY_SIMAVR_SAMPLE = ["fault_encoder_cut", "fault_encoder_cut_both", "fault_encoder_cut_fast_both",
                        "fault_encoder_reversed", "fault_wheel_locked", "fault_motor_dead",
                        "fault_encoder_noise_100k", "fault_reset", "fault_link_cut", "fault_silence"]


@pytest.mark.parametrize(("name", "backend"), cases([(n,) for n in FAULT_SCENARIOS], FAULT_SCENARIOS,
                                                    fast_simavr=SAFETY_SIMAVR_SAMPLE))
def test_safety_bounds(name: str, backend: str) -> None:
    """The safety bounds (docs/safety.md), per bundled fault scenario: on the firmware before the fix
    these fail (runaway, coasting, a starved control loop)."""
    r = _run(name, backend)
    if backend == "simavr":
        assert r.firmware_differences == 0
    problems = safety.violations(scenario.load(name), r)
    assert not problems, f"{name} on {backend}: " + "; ".join(problems)


def test_bounds_can_fail() -> None:
    """``violations`` is not vacuous: a chair that runs away after an encoder cut (the
    firmware before fault detection, simulated by forcing full duty) breaks every bound."""
    sc = scenario.load("fault_encoder_cut_both")
    r = _run("fault_encoder_cut_both", "port")
    truth = dataclasses.replace(r.truth, step_volts=np.full_like(r.truth.step_volts, 24.0),
                                step_speed=np.where(r.truth.step_time > 1.5, 1.9, r.truth.step_speed))
    bad = dataclasses.replace(r, link=dataclasses.replace(r.link, events=[]), truth=truth)
    problems = safety.violations(sc, bad)
    assert len(problems) == 4, problems
    assert safety.stopping_bound(1.95, 500) == pytest.approx(1.95 * 0.6 + 1.95**2 / (2 * 15 * 0.1524) + 0.1)


# ---- the stopping-distance benchmark ------------------------------------------------------
@pytest.fixture(scope="module")
def stopping() -> ModuleType:
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "stopping_distance.py"
    spec = importlib.util.spec_from_file_location("wcdrive_stopping_distance", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_stopping_distance_benchmark_runs(stopping: ModuleType) -> None:
    sc = stopping.scenario(1.0, 100)
    assert sc.board_params == {"watchdog_ms": 100.0} and sc.segments[-1].kind == "silence"
    row = stopping.measure(1.0, 100, "port")
    assert row.speed_at_last_byte == pytest.approx(1.0, abs=0.1)
    assert 0.0 < row.distance_m < 5.0
    chair = sc.params()
    decel = min(safety.EMERGENCY_DECEL, chair.max_braking / chair.wheel_radius)
    assert row.bound_m == pytest.approx(safety.stopping_bound(row.speed_at_last_byte, 100, decel))
    longer = stopping.measure(1.0, 1000, "port")
    assert longer.distance_m > row.distance_m + 0.5                # the watchdog setting took effect
    text = stopping.table([row, longer])
    assert "| port | 1.00 | 100 |" in text and "| port | 1.00 | 1000 |" in text


def test_max_braking_is_what_the_plant_does_at_full_reverse() -> None:
    """``ChairParams.max_braking`` (the bound's braking rate) against the plant: from
    1.95 m/s, full reverse duty (the driver at its current limit) stops the chair in
    v / max_braking, within 5 %."""
    from wcdrive.plant import ChairParams, Plant

    params = ChairParams()
    plant = Plant(params)
    while (plant.left.speed + plant.right.speed) / 2 * params.wheel_radius < 1.95:
        plant.set_drive(255, 1, 255, 1)
        plant.advance(1, 0.001)
    v0 = (plant.left.speed + plant.right.speed) / 2 * params.wheel_radius
    plant.set_drive(255, 0, 255, 0)
    t = 0.0
    while (plant.left.speed + plant.right.speed) / 2 * params.wheel_radius > 0.0:
        plant.advance(1, 0.001)
        t += 0.001
    assert t == pytest.approx(v0 / params.max_braking, rel=0.05)
