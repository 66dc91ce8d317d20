"""benchmarks/board_lines.py (R2, board to host) and benchmarks/soak.py in short runs:
no corrupted line believed and every line accounted for; a soak's checks met. The full
figures are in docs/benchmarks.md."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"wcdrive_bench_{name}", BENCHMARKS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_no_corrupted_board_line_is_accepted_and_every_line_is_counted() -> None:
    bench = _load("board_lines")
    f = bench.run("port", bench.port_lines(20.0, 3), 20_000, 3)
    assert f.corrupted > 5_000 and f.accepted == 0
    assert f.lines.spliced > 0 and f.lines.bad_crc > 0 and f.lines.lost > 0
    total = f.lines.total
    assert f.sent <= total <= f.sent + f.cuts


def test_the_benchmark_sees_a_host_that_skips_the_crc(monkeypatch: pytest.MonkeyPatch) -> None:
    """The break the note names: with ``crc16`` always 0, the frames the benchmark makes
    carry ``*0000`` and the decoder takes every frame's text as good."""
    bench = _load("board_lines")
    lines = bench.port_lines(10.0, 4)
    from wcdrive.protocol import codec

    monkeypatch.setattr(codec, "crc16", lambda data: 0)
    f = bench.run("port", lines, 5_000, 4)
    assert f.accepted > 100


def test_a_short_soak_meets_its_checks() -> None:
    soak = _load("soak")
    report = soak.soak("sim", 0.05, 100.0, 3)
    assert report.failures == [], report.failures
    assert report.sent_lines == report.lines.good > 5_000


def test_a_soaks_board_runs_again_bit_for_bit_from_its_record(tmp_path: Path) -> None:
    """The board of a soak on ``sim://`` is paced by the host's program and its input is
    recorded: ``replay`` runs the same board again without the host, to the same pose of
    the plant, so whatever a soak finds can be looked at tick by tick."""
    soak = _load("soak")
    record = tmp_path / "input.jsonl"
    report = soak.soak("sim", 0.05, 50.0, 5, record)
    assert report.failures == [], report.failures
    assert report.watchdog_while_driving == 0
    loop = soak.replay(record, 5)
    assert loop.plant.pose == report.final_truth


@pytest.mark.thorough
def test_the_soak_sees_a_host_that_leaks(monkeypatch: pytest.MonkeyPatch) -> None:
    """A host that keeps 1 kB for every read of the board's bytes: the soak's memory
    check, which starts at the 10-minute mark, goes red within 12 simulated minutes."""
    from wcdrive.protocol import codec

    soak = _load("soak")
    kept: list[bytes] = []
    feed = codec.LineDecoder.feed

    def leaky(self: codec.LineDecoder, data: bytes) -> list[codec.Message]:
        kept.append(bytes(1000))
        return feed(self, data)

    monkeypatch.setattr(codec.LineDecoder, "feed", leaky)
    report = soak.soak("sim", 0.2, 100.0, 3)
    assert any(f.startswith("host memory grew") for f in report.failures), report.failures


def test_a_line_a_reset_cuts_short_counts_as_sent() -> None:
    """On ``simavr://`` a line's bytes reach the link as they leave the UART, so a board
    reset can fall inside one; the host's decoder then counts the cut line on its own
    (split from the ``BOOT:`` after it), and the soak must count it as sent too. The
    same bytes through the host's decoder: the counts agree."""
    from wcdrive.protocol.codec import LineDecoder, board_frame

    soak = _load("soak")
    first, second = board_frame(b"ENC:1,2", 0), board_frame(b"ENC:3,4", 1)
    chunks = [first, second[:6], b"BOOT:reset\n"]

    class Board:
        def __init__(self) -> None:
            self.left = list(chunks)

        def _advance(self) -> bytes:
            return self.left.pop(0) if self.left else b""

    class Port:
        def reset_input_buffer(self) -> None:
            pass

    board = Board()
    sent = soak.SentLines(board, Port())
    decoder = LineDecoder()
    decoder.framed = True
    for _ in range(2):
        decoder.feed(board._advance())
    sent.reset()                                  # the DTR pulse: the second line is cut
    decoder.feed(board._advance())
    assert (sent.count, sent.cut) == (3, 1) == (decoder.stats.total, decoder.stats.bad_crc)


def test_the_soaks_slow_change_of_course_runs_again_without_a_fault() -> None:
    """The 24 h soak's first false ``FAULT,MOTOR_R`` (seed 1, 2,602 s in: the right
    wheel's duty rose 53 to 73 at 93 % of its setpoint while the left, ramped down at a
    low ``max_accel``, ran 1 rad/s beyond its own), its input kept in
    ``benchmarks/data``: the board runs it again, to the record's end, without a fault.
    The motor rule without its ``FAULT_EFFORT_OVERRUN`` latches it again."""
    soak = _load("soak")
    loop = soak.replay(BENCHMARKS / "data" / "soak_seed1_motor_r.jsonl.gz", 1)
    lines = b"".join(out for _, out in loop.take_output()).split(b"\n")
    assert loop.fw.state.faultFlags == 0
    assert not [line for line in lines if b"EVT:FAULT" in line]
    assert loop.plant.pose != (0.0, 0.0, 0.0)
