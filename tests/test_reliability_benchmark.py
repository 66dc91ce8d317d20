"""The reliability benchmark (benchmarks/reliability.py, issue #14) in a tiny run, so it
cannot rot: no motion from invalid input, no corrupted frame executed or ACKed, port =
firmware; and shown able to fail, on a port that takes unframed motion after hello or
frames with any CRC."""

from __future__ import annotations

import importlib.util
import random
import sys
from pathlib import Path
from types import ModuleType

import pytest

from wcdrive.firmware import commands
from wcdrive.protocol.codec import crc16, frame

PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "reliability.py"


@pytest.fixture(scope="module")
def rel() -> ModuleType:
    spec = importlib.util.spec_from_file_location("wcdrive_reliability_benchmark", PATH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module            # dataclasses look their module up
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


def test_quick_run_on_the_port(rel: ModuleType) -> None:
    res = rel.run(rel.QUICK, seed=3, simavr=False)
    assert rel.problems(res) == []
    for name, st in res.r1_port.items():
        assert st.invalid > 500, name
        assert (st.crashes, st.hangs, st.invalid_motions, st.invalid_param_changes) == (0, 0, 0, 0)
        assert st.controls["drive"] > 100 and st.controls_ok == st.controls, name
    assert res.r1_port["strict"].answers["random", "ERR:unframed"] > 0
    r2 = res.r2_port
    assert sum(r2.frames.values()) == rel.QUICK["port_frames"]
    assert sum(r2.executed.values()) == sum(r2.acked.values()) == 0
    assert r2.refused == r2.commands > rel.QUICK["port_frames"]
    # The legacy risk is real: a flipped bit in a bare v1 line often drives elsewhere.
    assert res.legacy.v1["1 bit", "different"] > 0
    text = rel.markdown(res)
    assert "| R1: " in text and "| R2: " in text and "| 1 bit |" in text


def test_command_line(rel: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    code = rel.main(["--quick", "--no-simavr", "--port-lines", "500", "--port-frames", "500",
                     "--legacy-frames", "500"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "No problem found." in out and "| test | on the port |" in out


@pytest.mark.simavr
def test_quick_run_on_the_firmware(rel: ModuleType, elf: Path) -> None:
    r1 = rel.firmware_r1(rel.QUICK["firmware_lines"], random.Random(5), elf)
    for name, st in r1.items():
        assert st.total > 0 and st.invalid > 0, name
        assert st.lockstep.mismatches == 0, st.lockstep.examples
        assert st.lockstep.lost_bytes == 0 and st.lockstep.extra_boots == 0
        assert (st.crashes, st.hangs, st.invalid_motions, st.invalid_param_changes) == (0, 0, 0, 0)
        assert st.controls_ok["drive"] == st.controls["drive"] > 0, st.examples
    r2 = rel.firmware_r2(rel.QUICK["firmware_frames"], random.Random(6), elf, chunk=200)
    assert r2.lockstep.mismatches == 0, r2.lockstep.examples
    assert sum(r2.executed.values()) == sum(r2.acked.values()) == 0
    assert r2.refused == r2.commands > rel.QUICK["firmware_frames"]


def test_it_sees_unframed_motion_after_hello(rel: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    """A port that lets an unframed motion through after hello fails R1."""
    monkeypatch.setattr(commands, "refused_unframed", lambda s, right, left: False)
    st = rel.port_r1(3000, random.Random(1), True)
    assert st.invalid_motions > 0
    assert any("drove" in e for e in st.examples)


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
