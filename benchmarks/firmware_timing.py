"""The firmware's timing budget, cycle by cycle, from the compiled ELF in
simavr: the harness charges each interrupt entry its 5 cycles, as the chip does.

    python benchmarks/firmware_timing.py            # the full run; --write puts the
    python benchmarks/firmware_timing.py --short    # table into docs/benchmarks.md
    python benchmarks/firmware_timing.py --minutes 10   # 10 minutes at top speed: the drift

It prints:

- every interrupt handler's cycles per path, from the disassembly (wcdrive.hil.isr_cycles:
  entry 5 + jmp 3 + the path to and with reti);
- the edge rate up to which every edge is counted, found by bisection, for one wheel and
  for both (coincident edges, and half an edge interval apart);
- the CPU load (cycles outside loop()'s idle polling) at 0, 14,000, 28,000 and 56,000
  edges/s per wheel, with a host saying hello (TLM lines on) and sending a command every
  50 ms;
- the control ticks' lateness (cycles from the Timer0 overflow that makes millis() reach
  the tick's due time to controlTick's entry) p50, p99 and max, and the grid's drift
  (millis() of the last tick against boot + 50 ms x ticks) at top speed (28,000 edges/s
  per wheel) with the command stream, and the ticks that ran at twice top speed.

Every figure is a cycle count of the simulation: nothing depends on wall time.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wcdrive.avr.timer0 import OVERFLOW_CYCLES, TIMER0_START_CYCLE, millis_after
from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.hil.isr_cycles import isr_paths
from wcdrive.plant.encoders import edges_from_trajectory
from wcdrive.protocol.codec import frame

HANDLERS = [("__vector_3", "INT2/INT3: right encoder"), ("__vector_5", "INT4/INT5: left encoder"),
            ("__vector_21", "TIMER0_COMPA: fold, storm windows"), ("__vector_23", "TIMER0_OVF: millis()"),
            ("__vector_25", "USART0_RX"), ("__vector_26", "USART0_UDRE")]
GOALS = {"isr": 60, "loss": 70_000, "load": 0.35, "late_ms": 1.0, "drift_ms_per_10min": 1.0}
ROOT = Path(__file__).resolve().parents[1]


def _symbols(elf: Path) -> dict[str, tuple[int, int]]:
    out = subprocess.run(["avr-nm", "-S", str(elf)], capture_output=True, text=True, check=True).stdout
    table = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 4:
            table[parts[3]] = (int(parts[0], 16), int(parts[1], 16))
    return table


def isr_rows(elf: Path) -> list[tuple[str, str, str]]:
    """(handler, what, cycles per path or why not counted)."""
    rows = []
    for symbol, what in HANDLERS:
        try:
            cycles = sorted({c for c, _ in isr_paths(elf, symbol)})
            rows.append((symbol, what, ", ".join(str(c) for c in cycles)))
        except ValueError as exc:
            rows.append((symbol, what, f"not a leaf: {exc}".split(": ", 2)[-1]))
    return rows


def _train(rate: float, start: float, seconds: float, sign: int = 1):
    return edges_from_trajectory(np.array([0.0, start, start + seconds]),
                                 np.array([0.5, 0.5, 0.5 + sign * rate * seconds]))


def all_counted(elf: Path, rate: float, both: bool, phase: float, seconds: float) -> bool:
    """Whether every edge at ``rate`` edges/s (on one wheel, or both with the right's
    edges ``phase`` of an interval after the left's) is counted, none illegal, no storm."""
    with VirtualMega(elf) as mega:
        left = _train(rate, 0.01, seconds)
        mega.encoder_edges("left", left)
        right = _train(rate, 0.01 + phase / rate, seconds, -1) if both else None
        if right is not None:
            mega.encoder_edges("right", right)
        mega.run_for(0.012 + seconds + 0.005)
        ok = mega.read("encoderValueL") == left.end_count and mega.read("illegalL") == 0
        ok = ok and mega.read("stormL") == 0
        if right is not None:
            ok = ok and mega.read("encoderValueR") == right.end_count and mega.read("illegalR") == 0
            ok = ok and mega.read("stormR") == 0
        return bool(ok)


def loss_threshold(elf: Path, both: bool, phase: float, seconds: float, steps: int) -> int:
    """The highest rate (edges/s per wheel, to 1,000) at which every edge is counted."""
    lo, hi = 20_000, 200_000
    if not all_counted(elf, lo, both, phase, seconds):
        return 0
    for _ in range(steps):
        if hi - lo <= 1000:
            break
        mid = (lo + hi) // 2
        if all_counted(elf, mid, both, phase, seconds):
            lo = mid
        else:
            hi = mid
    return lo


@dataclass
class Load:
    rate: float
    flood: bool
    load: float
    ticks: int
    late_p50_us: float
    late_p99_us: float
    late_max_us: float
    drift_ms: int
    late_ticks: int


def _commands(seconds: float, flood: bool) -> list[tuple[float, bytes]]:
    """hello, then a command every 50 ms, or (``flood``) frames back to back on the wire."""
    out = [(0.02, frame(b"hello", 1))]
    if flood:
        count = int((seconds - 0.06) * F_CPU / (1496 * 20))
        out.append((0.06, b"".join(frame(b"x:0.5,t:0.1", 2 + k % 60000) for k in range(count))))
        return out
    for k in range(int((seconds - 0.1) * 20)):
        out.append((0.06 + 0.05 * k, frame(b"x:0.5,t:0.1", 2 + k % 60000)))
    return out


def run_loaded(elf: Path, rate: float, seconds: float, flood: bool = False) -> Load:
    """The firmware with both wheels at ``rate`` edges/s (opposite directions: the left
    encoder counts down going forward) and the command stream: CPU load, tick lateness
    and the grid's drift."""
    sym = _symbols(elf)
    idle = [sym["main"], sym["_Z14serialEventRunv"]]
    with VirtualMega(elf) as mega:
        if rate:
            mega.encoder_edges("left", _train(rate, 0.01, seconds))
            mega.encoder_edges("right", _train(rate, 0.01, seconds, -1))
        for t, data in _commands(seconds, flood):
            mega.send(data, at=round(t * F_CPU))
        mega.run_for(0.1)                            # boot and hello; measure from here
        start = mega.cycle
        mega.profile([(a, a + n) for a, n in idle])
        boot = int(mega.read("lastControlTime"))
        first = int(mega.read("tickCount"))
        mega.take_hits()
        mega.run_for(seconds - 0.1)
        idle_cycles = sum(mega.profiled())
        ticks = [h for h in mega.take_hits() if h.function == "controlTick"]
        late_ticks = int(mega.read("lateTicks")) if "lateTicks" in mega.variables else -1
        total = mega.cycle - start
    lateness = []
    due = boot
    for k, hit in enumerate(ticks):
        due = boot + 50 * (k + 1)
        due_cycle = TIMER0_START_CYCLE + _due_overflow(due) * OVERFLOW_CYCLES
        lateness.append((hit.cycle - due_cycle) / F_CPU * 1e6)
    drift = int(ticks[-1].arg) - due if ticks else 0
    del first
    arr = np.array(lateness) if lateness else np.zeros(1)
    return Load(rate, flood, 1 - idle_cycles / total, len(ticks), float(np.percentile(arr, 50)),
                float(np.percentile(arr, 99)), float(arr.max()), drift, late_ticks)


def report(short: bool, elf: Path | None = None) -> tuple[str, dict[str, float]]:
    elf = elf or firmware_elf()
    seconds = 0.05 if short else 0.2
    steps = 6 if short else 8
    lines = ["| handler | cycles per path (entry and reti included) |", "|---|---|"]
    figures: dict[str, float] = {}
    for symbol, what, cycles in isr_rows(elf):
        lines.append(f"| `{symbol}` {what} | {cycles} |")
        if symbol in ("__vector_3", "__vector_5") and cycles[0].isdigit():
            counted = [int(c) for c in cycles.split(", ")][:2]   # step, illegal (not the storm's)
            figures[f"isr_{symbol}"] = max(counted)
    lines += ["", "| edges counted up to (edges/s per wheel) | |", "|---|---|"]
    for label, both, phase in (("one wheel", False, 0.0), ("both, coincident edges", True, 0.0),
                               ("both, half an interval apart", True, 0.5)):
        rate = loss_threshold(elf, both, phase, seconds, steps)
        figures[f"loss_{label}"] = rate
        lines.append(f"| {label} | {rate:,} |")
    lines += ["", "| edges/s per wheel | commands | CPU load | ticks | lateness p50 / p99 / max (µs) "
              "| grid drift (ms) | late ticks |", "|---|---|---|---|---|---|---|"]
    run_s = 2.0 if short else 20.0
    runs = [(0.0, False), (14_000.0, False), (28_000.0, False), (28_000.0, True), (56_000.0, True)]
    for rate, flood in runs:
        seconds_here = run_s if (rate, flood) == (28_000.0, True) else min(run_s, 2.0)
        r = run_loaded(elf, rate, seconds_here, flood)
        if not flood:
            figures[f"load_{int(rate)}"] = r.load
        if (rate, flood) == (28_000.0, True):
            figures.update(late_max_us=r.late_max_us, drift_ms=abs(r.drift_ms), late_ticks=r.late_ticks,
                           seconds=seconds_here, load_28000_flood=r.load)
        if rate == 56_000.0:
            figures["ticks_at_56k"] = r.ticks
            figures["ticks_expected_at_56k"] = int((seconds_here - 0.1) * 20)
        lines.append(f"| {rate:,.0f} | {'back to back' if flood else '20 Hz'} | {r.load:.1%} | {r.ticks} | "
                     f"{r.late_p50_us:.0f} / {r.late_p99_us:.0f} / {r.late_max_us:.0f} | {r.drift_ms} | "
                     f"{r.late_ticks} |")
    return "\n".join(lines), figures


def _due_overflow(due: int) -> int:
    """The first Timer0 overflow after which ``millis()`` has reached ``due``."""
    lo, hi = 0, (due + 2) * 2
    while lo < hi:
        mid = (lo + hi) // 2
        if millis_after(mid) >= due:
            hi = mid
        else:
            lo = mid + 1
    return lo


def long_run(elf: Path, minutes: float, rate: float = 28_000.0, chunk_s: float = 10.0) -> str:
    """``minutes`` simulated minutes at ``rate`` edges/s per wheel with v3 frames back to
    back after hello, fed to simavr ``chunk_s`` at a time (edges and bytes for the whole
    run at once would not fit in memory): the tick grid's drift over the run (the last
    tick's ``millis()`` against the first's + 50 ms x ticks), the ticks' lateness, late
    ticks, bytes lost, lines dropped."""
    byte_s = 1496 * 20 / F_CPU
    ticks = []
    with VirtualMega(elf) as mega:
        mega.send(frame(b"hello", 1), at=round(0.02 * F_CPU))
        total, t, seq, wire_free = minutes * 60, 0.0, 2, 0.06
        while t < total:
            end = min(total, t + chunk_s)
            for side, sign in (("left", 1), ("right", -1)):
                def at(x: float, sign: float = sign) -> float:    # the count at x s (from 10 ms)
                    return 0.5 + sign * rate * (x - 0.01)
                if t == 0.0:
                    times, counts = [0.0, 0.01, end], [0.5, 0.5, at(end)]
                else:
                    times, counts = [t, end], [at(t), at(end)]
                mega.encoder_edges(side, edges_from_trajectory(np.array(times), np.array(counts)))
            n = int((end - wire_free) / byte_s)
            if n > 0:
                mega.send(b"".join(frame(b"x:0.5,t:0.1", 2 + (seq + k) % 60000) for k in range(n)),
                          at=round(wire_free * F_CPU))
                seq, wire_free = seq + n, wire_free + n * byte_s
            mega.run_for(end - t)
            ticks += [h for h in mega.take_hits() if h.function == "controlTick"]
            t = end
        late_ticks, rx_lost, tx_dropped = (int(mega.read(v)) for v in ("lateTicks", "rxLost", "txDropped"))
    ms = np.array([int(h.arg) for h in ticks], dtype=np.int64)
    due_cycles = [TIMER0_START_CYCLE + _due_overflow(int(due)) * OVERFLOW_CYCLES for due in ms]
    late_us = np.array([(h.cycle - c) / F_CPU * 1e6 for h, c in zip(ticks, due_cycles, strict=True)])
    p50, p99 = np.percentile(late_us, 50), np.percentile(late_us, 99)
    return (f"{minutes:g} min at {rate:,.0f} edges/s per wheel, frames back to back: {len(ticks)} ticks, "
            f"grid drift {int(ms[-1] - ms[0] - 50 * (len(ms) - 1))} ms, lateness p50 / p99 / max "
            f"{p50:.0f} / {p99:.0f} / {late_us.max():.0f} µs, "
            f"late ticks {late_ticks}, bytes lost {rx_lost}, lines dropped {tx_dropped}")


def write(table: str) -> None:
    path = ROOT / "docs" / "benchmarks.md"
    text = path.read_text()
    start, end = "<!-- firmware_timing -->", "<!-- /firmware_timing -->"
    block = f"{start}\n{table}\n{end}"
    if start in text:
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    else:
        text += ("\n## Firmware timing\n\n`python benchmarks/firmware_timing.py --write`\n\n"
                 + block + "\n")
    path.write_text(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--short", action="store_true", help="short runs (the test suite's)")
    parser.add_argument("--write", action="store_true", help="put the table into docs/benchmarks.md")
    parser.add_argument("--elf", type=Path, help="another build of final_control (default: this one)")
    parser.add_argument("--minutes", type=float, metavar="M",
                        help="instead: M simulated minutes at top speed, the grid's drift (long_run)")
    args = parser.parse_args(argv)
    if args.minutes:
        print(long_run(args.elf or firmware_elf(), args.minutes))
        return 0
    table, figures = report(args.short, args.elf)
    print(table)
    print("figures:", {k: round(v, 4) if isinstance(v, float) else v for k, v in figures.items()})
    if args.write:
        write(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
