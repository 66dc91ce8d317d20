"""The reliability benchmark (benchmarks/reliability/, issue #14) in a tiny run, so it
cannot rot: no motion from invalid input, no corrupted frame executed or ACKed, no
motion while the board waits for neutral, port = firmware; and shown able to fail, on a
port that takes unframed motion after hello or frames with any CRC, on one that drives
while it waits for neutral, and without the neutral prelude."""

from __future__ import annotations

import importlib.util
import random
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from tests.conftest import thorough
from wcdrive.firmware import commands
from wcdrive.plant import ChairParams
from wcdrive.protocol.codec import crc16, frame

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
PACKAGE = BENCHMARKS / "reliability"


@pytest.fixture(scope="module")
def rel() -> ModuleType:
    """The package ``benchmarks/reliability/``, loaded by path (``benchmarks`` is not
    on the import path), its modules under ``wcdrive_reliability_benchmark.``."""
    spec = importlib.util.spec_from_file_location("wcdrive_reliability_benchmark", PACKAGE / "__init__.py",
                                                  submodule_search_locations=[str(PACKAGE)])
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module            # dataclasses and relative imports look it up
    spec.loader.exec_module(module)
    return module


def test_the_oracle_cuts_commands_as_the_protocol_says(rel: ModuleType) -> None:
    assert rel.split_commands(b"x:0.500,t:0.100,rp1,lp2,\n") == [b"x:0.500,t:0.100,", b"rp1,lp2,"]
    assert rel.split_commands(b"ab,x:1\r$1:x:1,t:2,*0000\n") == [b"ab,", b"x:1", b"$1:x:1,t:2,*0000"]
    assert rel.split_commands(b"x:" + b"1" * 70 + b",t:0,\n") == [None, b"t:0,"]
    good = frame(b"x:0.500,t:0.100,", 17)
    assert rel.line_valid(good, strict=True)
    assert not rel.line_valid(good.replace(b"0.500", b"0.501"), strict=True)
    assert not rel.line_valid(b"x:0.500,t:0.100,\n", strict=True)
    assert rel.line_valid(b"x:0.500,t:0.100,\n", strict=False)
    assert not rel.line_valid(b"x:2.7,t:0,\n", strict=False)


def test_quick_run_on_the_port(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """A port hang is wall-clock time (a line's ``feed`` over ``HANG_S``); beside a
    loaded test run a scheduler pause passed the benchmark's 50 ms, so here a hang is a
    line that takes a second. (The firmware's hang is counted in simulated cycles.)"""
    for name in ("r1", "r2"):
        monkeypatch.setattr(sys.modules[f"wcdrive_reliability_benchmark.{name}"], "HANG_S", 1.0)
    res = rel.run(rel.QUICK, seed=3, simavr=False)
    assert rel.problems(res) == []
    for name, st in res.r1_port.items():
        assert st.invalid > 500, name
        assert (st.crashes, st.hangs, st.invalid_motions, st.invalid_param_changes) == (0, 0, 0, 0)
        # Every valid drive carried out, but those that came while the board waited for
        # neutral (the stream's PPM loss frames and watchdog stops begin waits): refused.
        assert (st.neutral_motions, st.preludes_failed) == (0, 0), name
        assert st.neutral_waits > 10 and st.refused_neutral > 10, name
        assert st.controls_ok["drive"] > 100, name
        assert st.controls_ok["drive"] + st.refused_neutral == st.controls["drive"], name
        assert all(st.controls_ok[k] == st.controls[k] for k in ("stop", "param")), name
    assert res.r1_port["strict"].answers["random", "ERR:unframed"] > 0
    r2 = res.r2_port
    assert r2.preludes_failed == 0
    assert sum(r2.frames.values()) == rel.QUICK["port_frames"]
    assert sum(r2.executed.values()) == sum(r2.acked.values()) == 0
    assert r2.refused == r2.commands > rel.QUICK["port_frames"]
    # The legacy risk is real: a flipped bit in a bare v1 line often drives elsewhere.
    assert res.legacy.v1["1 bit", "different"] > 0
    text = rel.markdown(res)
    assert "| R1: " in text and "| R2: " in text and "| 1 bit |" in text


ARGS = ["--quick", "--no-simavr", "--port-lines", "500", "--port-frames", "500", "--legacy-frames", "500"]


def test_command_line(rel: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    code = rel.main(ARGS)
    out = capsys.readouterr().out
    assert code == 0, out
    assert "No problem found." in out and "| test | on the port |" in out


@pytest.mark.parametrize("command", [[str(BENCHMARKS / "reliability.py")], ["-m", "benchmarks.reliability"]],
                         ids=["script", "module"])
def test_the_documented_commands_run_it(command: list[str]) -> None:
    """``python benchmarks/reliability.py`` (docs/benchmarks.md) and ``python -m
    benchmarks.reliability`` (from the checkout) both run the package."""
    import subprocess

    done = subprocess.run([sys.executable, *command, *ARGS], cwd=BENCHMARKS.parent, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "No problem found." in done.stdout and "| test | on the port |" in done.stdout


@pytest.mark.simavr
@pytest.mark.thorough
def test_quick_run_on_the_firmware(rel: ModuleType, elf: Path) -> None:
    r1 = rel.firmware_r1(rel.QUICK["firmware_lines"], random.Random(5), elf)
    for name, st in r1.items():
        assert st.total > 0 and st.invalid > 0, name
        assert st.lockstep.mismatches == 0, st.lockstep.examples
        assert st.lockstep.lost_bytes == 0 and st.lockstep.extra_boots == 0
        assert (st.crashes, st.hangs, st.invalid_motions, st.invalid_param_changes) == (0, 0, 0, 0)
        assert (st.neutral_motions, st.preludes_failed) == (0, 0), st.examples
        assert st.controls_ok["drive"] > 0, name
        assert (st.controls_ok["drive"] + st.refused_latched + st.refused_neutral
                == st.controls["drive"]), st.examples
    assert sum(st.refused_neutral for st in r1.values()) > 0
    assert rel.problems(rel.Results(0, {}, r1_firmware=r1)) == []
    r2 = rel.firmware_r2(rel.QUICK["firmware_frames"], random.Random(6), elf, chunk=200)
    assert r2.preludes_failed == 0
    assert r2.lockstep.mismatches == 0, r2.lockstep.examples
    assert sum(r2.executed.values()) == sum(r2.acked.values()) == 0
    assert r2.refused == r2.commands > rel.QUICK["firmware_frames"]


def test_it_sees_unframed_motion_after_hello(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """A port that lets an unframed motion through after hello fails R1."""
    monkeypatch.setattr(commands, "refused_unframed", lambda s, right, left: False)
    st = rel.port_r1(3000, random.Random(1), True)
    assert st.invalid_motions > 0
    assert any("drove" in e for e in st.examples)


def test_it_sees_motion_while_the_board_waits_for_neutral(rel: ModuleType,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A port that drives while it waits for neutral fails R1: the motion is a safety
    violation, not a valid drive carried out."""
    monkeypatch.setattr(commands, "refused_not_neutral", lambda s, right, left: False)
    st = rel.port_r1(3000, random.Random(1), True)
    assert st.neutral_motions > 0 and st.refused_neutral == 0
    assert any("waited for neutral" in e for e in st.examples)
    res = rel.Results(1, {})
    res.r1_port["strict"] = st
    assert any("motions while the board waited for neutral" in p for p in rel.problems(res))


def test_it_sees_a_run_without_its_neutral_prelude(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the prelude the board refuses every drive (``neutral``) until a stop in the
    stream stands, refusals the oracle would take for correct: the run is a problem."""
    r1 = sys.modules["wcdrive_reliability_benchmark.r1"]
    monkeypatch.setattr(r1, "neutral_prelude", lambda strict: b"")
    res = rel.Results(1, {})
    res.r1_port["strict"] = st = rel.port_r1(500, random.Random(1), True)
    assert st.preludes_failed == 1
    assert any("neutral preludes" in p for p in rel.problems(res)), rel.problems(res)


@pytest.mark.simavr
def test_it_sees_a_port_that_differs_from_the_firmware(rel: ModuleType, elf: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The same bug in the port alone: the lock-step comparison reports it."""
    monkeypatch.setattr(commands, "refused_unframed", lambda s, right, left: False)
    r1 = rel.firmware_r1(100, random.Random(5), elf, chunk=50)
    assert r1["strict"].lockstep.mismatches > 0
    assert "mismatches" in " ".join(rel.problems(rel.Results(0, {}, r1_firmware=r1)))


def test_it_sees_a_frame_taken_with_a_bad_crc(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """A port that takes any four hex digits as the CRC fails R2."""
    strict_unframe = commands.unframe

    def lax(buf: bytes) -> tuple[str | None, int, bytes]:
        n = len(buf)
        if n >= 6 and buf[n - 5] == 0x2A and all(c in b"0123456789ABCDEF" for c in buf[n - 4:]):
            buf = buf[:n - 4] + b"%04X" % crc16(buf[1:n - 5])
        return strict_unframe(buf)

    monkeypatch.setattr(commands, "unframe", lax)
    r2 = rel.port_r2(2000, random.Random(2))
    assert sum(r2.acked.values()) > 0 and sum(r2.executed.values()) > 0


def test_answers_are_read_through_their_v4_frames(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """The board says hello:4 in R1 and R2, so its answers come framed: they are read
    unframed, and one that fails its check is a problem R1 reports."""
    from wcdrive.firmware import output
    from wcdrive.protocol.codec import board_frame

    common = sys.modules["wcdrive_reliability_benchmark.common"]
    assert common.answer_kinds(board_frame(b"NAK:7,checksum", 3) + board_frame(b"ACK:8", 4)) == [
        "NAK:checksum", "ACK"]
    assert common.answer_kinds(b"ACK:8#04*0000\r\n") == ["BAD FRAME"]
    monkeypatch.setattr(output, "board_frame", lambda text, n: board_frame(text, n)[:-4] + b"00\r\n")
    res = rel.Results(1, {})
    res.r1_port["strict"] = rel.port_r1(300, random.Random(1), True)
    assert any("failed their v4 check" in p for p in rel.problems(res)), rel.problems(res)


# ---- R3: link cut, unplug and DTR reset mid-motion ----------------------------------------
def unknown_problems(rel: ModuleType, r: Any) -> list[str]:
    """R3's problems, headlines only. (Two host defects R3 found were allowed for here
    until they were fixed: a ``BOOT:`` line glued to a line the reset cut, and hellos
    retried on each ERR until the board's answer budget ran out. Its stop bound then
    assumed braking at 15 rad/s^2, twice what the motors give.)"""
    return [line for line in rel.r3_problems(r) if not line.startswith("  ")]


def test_r3_bounds_and_analysis(rel: ModuleType) -> None:
    # watchdog 0.5 s, 1 m/s = 6.56 rad/s at 15 rad/s^2, two 50 ms ticks
    braking = ChairParams().max_braking                      # 1.12 m/s^2 < 15 rad/s^2 at the rim
    assert rel.stop_bound(1.0) == pytest.approx(0.6 + 1.0 / braking + 0.1)
    assert rel.stop_bound(1.0, watchdog=False) == pytest.approx(1.0 / braking + 0.1)
    assert rel.travel_bound(1.0) == pytest.approx(0.6 + 1.0 / (2 * braking) + 0.1)
    f = 16_000_000
    samples = [(0, 50, 50, 0.5, 0.0, 0.0), (f // 2, 20, 20, 0.2, 0.2, 0.0), (f, 0, 0, 0.005, 0.3, 0.0),
               (f + f // 10, 3, 0, 0.02, 0.3, 0.1), (2 * f, 0, 0, 0.0, 0.3, 0.1)]
    pwm_zero, still, travel = rel.analyse_stop(samples, 0, 2 * f)
    assert (pwm_zero, still, travel) == (2.0, 2.0, pytest.approx(0.4))
    assert rel.analyse_stop(samples, 0, f) == (1.0, 1.0, pytest.approx(0.3))
    assert rel.analyse_stop(samples, 3 * f, 4 * f) == (None, None, 0.0)
    assert rel.executed_before_hello(b"ACK:1\r\nENC:1,2BOOT:x,EXTERNAL\r\nACK:2\r\nACK:3\r\n") == 2
    assert rel.executed_before_hello(b"BOOT:x,EXTERNAL\r\nHELLO:3,x\r\nACK:2\r\n") == 0


def test_r3_reports_what_went_wrong(rel: ModuleType) -> None:
    """The checks can fail: a late stop, a reset the host missed, a frame executed twice."""
    late = rel.R3Trial("link cut", 1.0, rel.stop_bound(1.0), rel.travel_bound(1.0), pwm_before=(60, 60),
                       pwm_zero_s=rel.stop_bound(1.0) + 0.2, noticed_s=0.15, recovered_s=0.01)
    missed = rel.R3Trial("DTR reset", 1.0, rel.stop_bound(1.0, False), rel.travel_bound(1.0, False),
                         pwm_before=(60, 60), pwm_after=(0, 0), pwm_zero_s=0.2, boot_cause="EXTERNAL",
                         executed_before_hello=4)
    good = rel.R3Trial("unplug", 1.0, rel.stop_bound(1.0), rel.travel_bound(1.0), pwm_before=(60, 60),
                       pwm_zero_s=0.9, noticed_s=0.02, recovered_s=0.2, rehandshake=True,
                       boot_cause="EXTERNAL")
    r = rel.R3Result(trials={"link cut": [late], "unplug": [good], "DTR reset": [missed]}, acked=10,
                     executed_twice=[7])
    found = rel.r3_problems(r)
    assert "R3 link cut: 1 stops late or never (PWM)" in found
    assert "R3 DTR reset: 1 faults the host did not notice" in found
    assert "R3 DTR reset: 1 re-handshakes missing" in found
    assert not any(line.startswith("R3 unplug") for line in found)
    assert "R3: sequence numbers executed twice: [7]" in found
    assert "| DTR reset | 1 |" in "\n".join(rel.r3_table(r))
    assert unknown_problems(rel, r) != []


@pytest.mark.simavr
def test_r3_faults_mid_motion_on_the_firmware(rel: ModuleType, elf: Path) -> None:
    """Two of each fault on the live board (one at the fast depth), at half real time
    (the host's clock alike, so that a loaded machine does not starve it): the chair
    stops, the host notices and drives again, no frame is executed twice."""
    each = 2 if thorough() else 1
    r = rel.firmware_r3(each, random.Random(3), elf, pace=0.5)
    print("\n".join(rel.r3_table(r)))
    assert unknown_problems(rel, r) == [], rel.r3_problems(r)
    assert r.acked > 50 and r.executed_twice == []
    link_timeout = 3 * 0.050
    for kind, trials in r.trials.items():
        assert len(trials) == each
        for t in trials:
            assert min(t.pwm_before) > 0, t                      # mid-motion
            if kind == "DTR reset":
                assert t.pwm_after == (0, 0), t                  # from its first instruction
                assert t.noticed_by == "BOOT" and t.noticed_s < 0.1, t
            else:
                assert t.noticed_s is not None and t.noticed_s <= link_timeout + 0.05, t
            assert t.pwm_zero_s is not None and t.standstill_s is not None, t   # it stops
            assert t.travel_m <= t.travel_bound_m, t
            assert t.recovered_s is not None, t
            if kind != "link cut":
                assert t.rehandshake and t.boot_cause == "EXTERNAL", t
            if kind == "unplug":
                assert t.executed_before_hello == 0, t       # the host says hello before it drives
