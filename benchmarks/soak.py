"""The soak: a simulated chair driven for hours through the whole host stack
(``Wheelchair`` over ``wcsim://`` or ``wcavr://``, protocol v4), as navigation code
would drive it, with the figures of docs/benchmarks.md's "Soak".

    python benchmarks/soak.py [--hours 24] [--speed 100] [--backend sim|simavr] [--seed 1]

Random but plausible driving on the board's clock: drives (0.1 to 1.0 m/s forward,
0.3 m/s back, turns up to 0.8 rad/s) and stands, every command resent each 0.1 s; now
and then a pause that lets the board's watchdog stop the chair, a parameter change
(``max_accel``, ``watchdog_ms``), an e-stop and its reset, and a board reset (a DTR
pulse, as a reopened port or a brown-out). The report, and the check of each:

- host memory (``tracemalloc``) after the first simulated 10 minutes and at the end:
  flat (a bound below);
- every line accounted for: the lines the board sent (counted where the board hands
  them to the link) against ``chair.link_stats`` (good + bad CRC + spliced + lost);
- the odometry continuous across board resets (the pose after each ``Reset`` within
  1 cm of the pose before it);
- no gap between ticks over 60 ms of board time (``TLM``'s millis; none across a reset);
- no unexpected event: only ``WATCHDOG`` after a pause, ``ESTOP`` after an e-stop,
  ``BOARD_RESET`` and ``PARAMS_*`` after a reset.

``--hours`` of simulated time take ``hours * 3600 / speed`` s of wall time at best (the
host sleeps on the wall clock, 0.1 s of board time between commands). Exits 1 when a
check fails.
"""

from __future__ import annotations

import argparse
import collections
import gc
import json
import random
import sys
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import serial

import wcdrive
from wcdrive.host.telemetry import Reset, Telemetry
from wcdrive.protocol.codec import Event, LineStats

#: bytes the host may grow by from the 10-minute mark to the end.
MEMORY_BOUND = 300_000
#: s of board time between ticks beyond which a gap is reported.
TICK_GAP = 0.060
EXPECTED_EVENTS = ("WATCHDOG", "ESTOP", "BOARD_RESET", "PARAMS_LOADED", "PARAMS_DEFAULT")


@dataclass
class Report:
    backend: str
    hours: float
    speed: float
    seed: int
    wall_s: float = 0.0
    memory_start: int = 0
    memory_middle: int = 0
    memory_end: int = 0
    #: where the memory grew from the 10-minute mark to the end: "file:line +N kB"
    memory_growth: list[str] = field(default_factory=list)
    sent_lines: int = 0
    lines: LineStats = field(default_factory=LineStats)
    board_resets: int = 0
    worst_reset_jump_m: float = 0.0
    estops: int = 0
    pauses: int = 0
    #: watchdog stops while the host kept sending every 0.1 s: a host loop starved of
    #: CPU at this speed (not a check: a figure of the machine).
    watchdog_while_driving: int = 0
    param_changes: int = 0
    ticks: int = 0
    tick_gaps: list[float] = field(default_factory=list)
    unexpected_events: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


class SentLines:
    """Counts the lines the board hands to the link, from the board's own thread;
    ``freeze()`` stops the board where it is (its clock too), so that the host can read
    the last of them before the count is compared."""

    def __init__(self, board: object, port: serial.SerialBase) -> None:
        self.count = 0
        self.frozen = True
        self._advance = board._advance            # type: ignore[attr-defined]
        board._advance = self._counted            # type: ignore[attr-defined]
        time.sleep(0.05)
        port.reset_input_buffer()                 # what came before the count started
        self.frozen = False

    def _counted(self) -> bytes:
        if self.frozen:
            time.sleep(0.001)
            return b""
        out: bytes = self._advance()
        self.count += out.count(b"\n")
        return out

    def freeze(self, port: serial.SerialBase, lines_read: Callable[[], int]) -> None:
        """Stops the board, then waits until the host has read its last line: nothing
        waits in ``port`` and ``lines_read`` has not moved for 0.5 s."""
        self.frozen = True
        deadline = time.monotonic() + 10.0
        last, since = -1, time.monotonic()
        while time.monotonic() < deadline:
            now = lines_read()
            if now != last or port.in_waiting:
                last, since = now, time.monotonic()
            elif time.monotonic() - since > 0.5:
                return
            time.sleep(0.02)


def soak(backend: str, hours: float, speed: float, seed: int) -> Report:
    rng = random.Random(seed)
    report = Report(backend, hours, speed, seed)
    url = f"wcsim://?speed={speed:g}&seed={seed}" if backend == "sim" else f"wcavr://?speed={speed:g}"
    port = serial.serial_for_url(url, timeout=0.05)
    board = port.board
    sent = SentLines(board, port)
    last_millis: list[int | None] = [None]
    resets: list[tuple[tuple[float, float, float], Reset]] = []
    chair = wcdrive.Wheelchair(port, link_timeout=5.0)
    before_reset: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)]

    def on_tick(t: Telemetry) -> None:
        report.ticks += 1
        if t.extended is None:
            return
        millis = t.extended.millis
        if last_millis[0] is not None and millis > last_millis[0]:
            gap = (millis - last_millis[0]) / 1000.0
            if gap > TICK_GAP:
                report.tick_gaps.append(gap)
        last_millis[0] = millis

    def on_reset(r: Reset) -> None:
        last_millis[0] = None
        resets.append((before_reset[0], r))

    event_counts: collections.Counter[str] = collections.Counter()   # every event, unbounded
    on_event = chair._session._dispatch[Event]

    def count_event(now: float, msg: Event) -> None:
        event_counts[msg.name] += 1
        on_event(now, msg)
    chair._session._dispatch[Event] = count_event

    chair.on_telemetry(on_tick)
    chair.on_reset(on_reset)
    tracemalloc.start()
    started = time.monotonic()
    try:
        chair.wait_for_handshake(10.0)
        chair.history_limit = 1000
        end = hours * 3600.0
        expect: set[str] = set()
        marked = False
        first: tracemalloc.Snapshot | None = None
        while board.time < end:
            if not marked and board.time >= 600.0:
                gc.collect()
                report.memory_start = tracemalloc.get_traced_memory()[0]
                first = tracemalloc.take_snapshot()
                marked = True
            if not report.memory_middle and board.time >= end / 2 and marked:
                gc.collect()
                report.memory_middle = tracemalloc.get_traced_memory()[0]
            kind = rng.choices(("drive", "stand", "pause", "param", "estop", "reset"),
                               (70, 20, 4, 3, 2, 1))[0]
            length = rng.uniform(2.0, 20.0)
            linear, angular = 0.0, 0.0
            if kind == "drive":
                linear = rng.choice((rng.uniform(0.1, 1.0), -rng.uniform(0.1, 0.3)))
                angular = rng.uniform(-0.8, 0.8)
            elif kind == "pause":
                report.pauses += 1
                expect.add("WATCHDOG")
                chair.stop()
                _wait(board, rng.uniform(1.0, 3.0), speed)
                continue
            elif kind == "param":
                report.param_changes += 1
                name, value = rng.choice((("max_accel", rng.uniform(1.0, 4.0)),
                                          ("watchdog_ms", float(rng.choice((300, 500, 1000))))))
                chair.set_param(name, value)
            elif kind == "estop":
                report.estops += 1
                expect.add("ESTOP")
                chair.estop()
                _wait(board, 2.0, speed)
                chair.reset_estop(timeout=10.0)
                continue
            elif kind == "reset":
                report.board_resets += 1
                expect.update(("BOARD_RESET", "PARAMS_LOADED", "PARAMS_DEFAULT"))
                chair.stop()
                _wait(board, 2.0, speed)                  # at rest: the pose is final
                at_rest = chair.odometry.pose
                before_reset[0] = (at_rest.x, at_rest.y, at_rest.theta)
                # the host reads every line first: a DTR pulse drops what waits unread
                # (as on a real port), and those lines would be neither read nor lost
                sent.freeze(port, lambda: chair.link_stats.total)
                board.dtr()
                sent.frozen = False
                chair.wait_for_handshake(10.0)
                _wait(board, 0.5, speed)
                continue
            stop_at = board.time + length
            watchdogs = event_counts["WATCHDOG"]
            while board.time < stop_at:
                try:
                    chair.set_velocity(linear, angular)
                except wcdrive.WcdriveError as exc:
                    report.failures.append(f"{board.time:.1f} s: {exc}")
                    break
                _wait(board, 0.1, speed)
            report.watchdog_while_driving += event_counts["WATCHDOG"] - watchdogs
        chair.stop()
        _wait(board, 2.0, speed)
        gc.collect()
        report.memory_end = tracemalloc.get_traced_memory()[0]
        if first is None:
            report.memory_start = report.memory_end
        else:
            grown = tracemalloc.take_snapshot().compare_to(first, "lineno")
            report.memory_growth = [f"{st.traceback[0].filename}:{st.traceback[0].lineno} "
                                    f"{st.size_diff / 1e3:+.0f} kB ({st.count_diff:+d} blocks)"
                                    for st in grown[:8] if st.size_diff > 0]
        events = list(event_counts) + [e for e in chair.events if e not in event_counts]
        sent.freeze(port, lambda: chair.link_stats.total)
        stats = chair.link_stats
    finally:
        tracemalloc.stop()
        chair.close()
    report.wall_s = time.monotonic() - started
    report.sent_lines = sent.count
    report.lines = stats
    for (x, y, _), r in resets:
        jump = ((r.pose[0] - x) ** 2 + (r.pose[1] - y) ** 2) ** 0.5
        report.worst_reset_jump_m = max(report.worst_reset_jump_m, jump)
    allowed = tuple(e for e in EXPECTED_EVENTS if e in expect or e.startswith("PARAMS"))
    report.unexpected_events = sorted({e for e in events if not e.startswith(allowed)})
    _judge(report)
    return report


def _wait(board: object, seconds: float, speed: float) -> None:
    """Sleeps until the board's clock has moved ``seconds`` on."""
    until = board.time + seconds                  # type: ignore[attr-defined]
    while board.time < until:                     # type: ignore[attr-defined]
        time.sleep(min(0.1, seconds) / speed)


def _judge(r: Report) -> None:
    growth = r.memory_end - r.memory_start
    if growth > MEMORY_BOUND:
        r.failures.append(f"host memory grew {growth / 1e3:.0f} kB (bound {MEMORY_BOUND / 1e3:.0f} kB)")
    n = r.lines
    if n.total != r.sent_lines:
        r.failures.append(f"lines: {r.sent_lines} sent, {n.good} + {n.bad_crc} + {n.spliced} + {n.lost} "
                          "accounted for")
    if r.worst_reset_jump_m > 0.01:
        r.failures.append(f"the odometry jumped {r.worst_reset_jump_m:.3f} m across a reset")
    if r.tick_gaps:
        r.failures.append(f"{len(r.tick_gaps)} tick gaps over {TICK_GAP * 1000:.0f} ms "
                          f"(largest {max(r.tick_gaps) * 1000:.0f} ms)")
    if r.unexpected_events:
        r.failures.append(f"unexpected events: {', '.join(r.unexpected_events)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--speed", type=float, default=100.0)
    ap.add_argument("--backend", choices=("sim", "simavr"), default="sim")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    r = soak(args.backend, args.hours, args.speed, args.seed)
    if args.json:
        print(json.dumps(asdict(r), indent=2))
    else:
        print(f"soak on {r.backend}: {r.hours:g} simulated h at {r.speed:g}x in {r.wall_s:.0f} s wall")
        print(f"host memory after 10 min / half-way / at the end: {r.memory_start / 1e6:.3f} / "
              f"{r.memory_middle / 1e6:.3f} / {r.memory_end / 1e6:.3f} MB "
              f"({(r.memory_end - r.memory_start) / 1e3:+.0f} kB)")
        for site in r.memory_growth:
            print(f"  grew at {site}")
        n = r.lines
        print(f"lines sent {r.sent_lines}: good {n.good}, bad CRC {n.bad_crc}, spliced {n.spliced}, "
              f"lost {n.lost}")
        print(f"ticks {r.ticks}; gaps over {TICK_GAP * 1000:.0f} ms: {len(r.tick_gaps)}")
        print(f"board resets {r.board_resets} (largest odometry jump {r.worst_reset_jump_m * 1000:.2f} mm), "
              f"e-stops {r.estops}, watchdog pauses {r.pauses}, parameter changes {r.param_changes}")
        print(f"watchdog stops while the host drove (its loop starved at this speed): "
              f"{r.watchdog_while_driving}")
        print(f"unexpected events: {', '.join(r.unexpected_events) or 'none'}")
        print("checks: " + ("all met" if not r.failures else "FAILED: " + "; ".join(r.failures)))
    return 1 if r.failures else 0


if __name__ == "__main__":
    sys.exit(main())
