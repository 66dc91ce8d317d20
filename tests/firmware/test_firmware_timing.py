"""The firmware's timing budget, in cycles: the encoder interrupts' paths read
from the ELF's disassembly, and benchmarks/firmware_timing.py's short run on simavr (the
harness charging each interrupt entry its 5 cycles). Nothing here looks at wall time."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from wcdrive.boards.simavr.virtual_mega import F_CPU
from wcdrive.hil.isr_cycles import ENTRY_CYCLES, isr_paths
from wcdrive.hil.trace_base import MAX_TRACE_EDGE_RATE

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


#: The chair's top speed in encoder edges/s a wheel (17.59 rad/s).
TOP_SPEED_EDGES = 28_000
#: The longest AVR instruction (call, ret): the one instruction of loop() the chip runs
#: after a reti before it takes the next pending interrupt.
LONGEST_INSTRUCTION = 5
#: An encoder handler's cycles up to and including its read of the pins: the entry and
#: jmp, saving 8, the ``in`` 1 (the hand count in final_control.ino's comments).
TO_THE_PIN_READ = ENTRY_CYCLES + 8 + 1


def test_the_traces_edge_rate_is_within_what_the_encoders_count_under_a_flood(elf) -> None:
    """The longest an edge of the left encoder (INT4/INT5, below INT2/INT3 in priority)
    waits before its handler reads the pins: a receive interrupt (not interruptible)
    begun just before it, on its longest path (the ring full, a byte lost: a flood); an
    instruction of loop(); the right encoder's handler, pending too and first by
    priority; another instruction; its own handler up to the read. The next edge of that
    encoder must come later, or the handler reads two steps at once: an illegal
    transition and two edges lost. The generated traces' top rate keeps 10 % under that
    (the thorough CI drew a trace at 57,720 edges/s under a flood that merged two edges,
    with the cap at 60,000), and the bound itself is at least twice the top speed."""
    # the serial line's handlers (receive, transmit): the others open with sei
    blocking = max(c for vector in ("__vector_25", "__vector_26") for c, _ in isr_paths(elf, vector))
    right = max(c for c, _ in isr_paths(elf, "__vector_3"))
    wait = blocking + LONGEST_INSTRUCTION + right + LONGEST_INSTRUCTION + TO_THE_PIN_READ
    bound = F_CPU / wait
    assert MAX_TRACE_EDGE_RATE <= 0.9 * bound, (wait, bound)
    assert bound >= 2 * TOP_SPEED_EDGES, (wait, bound)


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
