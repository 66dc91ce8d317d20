"""The firmware's timing budget, in cycles: the encoder interrupts' paths read
from the ELF's disassembly, and benchmarks/firmware_timing.py's short run on simavr (the
harness charging each interrupt entry its 5 cycles). Nothing here looks at wall time."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from wcdrive.hil.isr_cycles import ENTRY_CYCLES, isr_paths

pytestmark = pytest.mark.simavr

ROOT = Path(__file__).resolve().parents[2]
#: The budget: an encoder interrupt, entry to reti, the 5-cycle entry included.
ISR_BUDGET = 60
#: The path of a storm's last edge (it masks the encoder: once per storm, then silence).
STORM_PATH_BUDGET = 66


@pytest.mark.parametrize("vector", ["__vector_3", "__vector_5"])
def test_every_counting_path_of_an_encoder_interrupt_is_within_the_budget(elf, vector: str) -> None:
    paths = sorted(c for c, _ in isr_paths(elf, vector))
    # four paths: a step, an illegal transition, and each of them as a storm's last edge
    assert len(paths) == 4, paths
    step, illegal, _storm_step, storm_illegal = paths
    assert step <= illegal <= ISR_BUDGET, paths
    assert storm_illegal <= STORM_PATH_BUDGET, paths
    assert step > ENTRY_CYCLES + 5                   # a real count, not an empty handler


def test_the_path_walker_agrees_with_the_hand_count(elf) -> None:
    """The left encoder's step path, counted by hand in final_control.ino's comments:
    entry 5 + jmp 3 + saving 8 + reading and the table 12 + the storm countdown 6 + the
    step's test 2 + the accumulator 5 + restoring and reti 13 = 54. A handler with a call
    (the control tick) is refused, not guessed."""
    assert isr_paths(elf, "__vector_5")[0][0] == 54
    with pytest.raises(ValueError, match="not a leaf"):
        isr_paths(elf, "controlTick")


def _benchmark():
    path = ROOT / "benchmarks" / "firmware_timing.py"
    spec = importlib.util.spec_from_file_location("firmware_timing", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["firmware_timing"] = module
    spec.loader.exec_module(module)
    return module


def test_the_timing_goals_hold_in_the_short_run() -> None:
    bench = _benchmark()
    table, figures = bench.report(short=True)
    assert "INT4/INT5" in table and "lateness" in table
    for label in ("one wheel", "both, coincident edges", "both, half an interval apart"):
        assert figures[f"loss_{label}"] >= 70_000, (label, figures)
    assert figures["load_28000"] <= 0.35
    assert figures["late_max_us"] <= 1000
    assert figures["drift_ms"] == 0 and figures["late_ticks"] == 0
    assert figures["ticks_at_56k"] == figures["ticks_expected_at_56k"]
