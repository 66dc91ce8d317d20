"""The soak: a simulated chair driven for hours through the whole host stack
(``Wheelchair`` over ``wcsim://`` or ``wcavr://``, protocol v4), as navigation code
would drive it, with the figures of docs/benchmarks.md's "Soak".

    python benchmarks/soak.py [--hours 24] [--speed 100] [--backend sim|simavr] [--seed 1]

Random but plausible driving on the board's clock: drives (0.1 to 1.0 m/s forward,
0.3 m/s back, turns up to 0.8 rad/s) and stands, every command resent each 0.1 s; now
and then a pause that lets the board's watchdog stop the chair, a parameter change
(``max_accel``, ``watchdog_ms``), an e-stop and its reset, and a board reset (a DTR
pulse, as a reopened port or a brown-out). The report, and the check of each:

- host memory (``tracemalloc``) after the first simulated 10 minutes, half-way and at
  the end: flat from half-way to the end (a bound below; from 10 minutes on when
  half-way comes first). The first half may grow by what fills once: the port's two
  parse caches (``functools.lru_cache``, 1,024 entries each, a few hundred kB full)
  fill over hours of random commands. A leak grows in both halves; the growth of each
  is printed with its sites;
- every line accounted for: the lines the board sent (counted where the board hands
  them to the link) against ``chair.link_stats`` (good + bad CRC + spliced + lost);
- the odometry continuous across board resets (the pose after each ``Reset`` within
  1 cm of the pose before it);
- no gap between ticks over 60 ms of board time (``TLM``'s millis; none across a reset);
- no unexpected event: only ``WATCHDOG`` after a pause, ``ESTOP`` after an e-stop,
  ``BOARD_RESET`` and ``PARAMS_*`` after a reset, ``NOT_NEUTRAL`` and ``NEUTRAL`` after
  a stall (the watchdog stopped the chair in it, and the command the host drove on with
  went out before it read so: refused until its neutral, docs/safety.md "Neutral before
  motion").

On ``sim://`` the board is paced by the host's program (``HostPacedClock``): it runs,
at most ``speed`` times the wall clock, only as far as the host's next step (0.1 s of
board time between commands, or the length of a pause), and runs freely only while the
host waits for an answer. So the only silences are those the program makes, as a
navigation stack's own: pauses at rest, and stalls in the middle of a drive (a host
that stops sending for 0.2 to 1.5 s, as a garbage collection, a swapped-out process or
a USB hiccup makes, then drives on), each counted. A board paced by the wall clock
alone at 30x or more measures the machine's scheduler instead: the host's loop starves
now and then and the watchdog stops the chair where no program paused
(``watchdog_while_driving`` counts such stops; 0 when paced by the host). On
``simavr://`` (1x) the wall clock paces the board.

``--hours`` of simulated time take ``hours * 3600 / speed`` s of wall time at best.
Exits 1 when a check fails.
"""

from __future__ import annotations

import argparse
import collections
import gc
import gzip
import json
import math
import random
import sys
import time
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import serial

import wcdrive
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.sim_board import GYRO_HISTORY
from wcdrive.errors import WcdriveNeutralError
from wcdrive.host.telemetry import Reset, Telemetry
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.protocol.codec import Event, LineStats

#: bytes the host may grow by from half-way to the end (from the 10-minute mark when
#: half-way comes first).
MEMORY_BOUND = 300_000
#: s of board time between ticks beyond which a gap is reported.
TICK_GAP = 0.060
EXPECTED_EVENTS = ("WATCHDOG", "ESTOP", "BOARD_RESET", "PARAMS_LOADED", "PARAMS_DEFAULT",
                   "NOT_NEUTRAL", "NEUTRAL")


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
    #: the same from half-way to the end
    memory_growth_late: list[str] = field(default_factory=list)
    #: the plant's pose at the end (x, y, heading): ground truth, and a replay's check
    final_truth: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sent_lines: int = 0
    cut_lines: int = 0           # of those, cut short by a board reset
    lines: LineStats = field(default_factory=LineStats)
    board_resets: int = 0
    worst_reset_jump_m: float = 0.0
    estops: int = 0
    pauses: int = 0
    #: drives in which the host fell silent for 0.2 to 1.5 s and then drove on
    stalls: int = 0
    #: watchdog stops while the host kept sending every 0.1 s: a host loop starved of
    #: CPU at this speed (not a check: a figure of the machine).
    watchdog_while_driving: int = 0
    param_changes: int = 0
    ticks: int = 0
    tick_gaps: list[float] = field(default_factory=list)
    unexpected_events: list[str] = field(default_factory=list)
    #: board time and name of the first 50 events not in EXPECTED_EVENTS
    event_log: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


class HostPacedClock:
    """The board's pacing clock held to the host's program: the board reaches the time
    the wrapped clock (``WallClock``) gives, but never past ``until``, which the host
    moves on as its program goes; while the host waits for an answer (``answering``)
    the board runs at real time from where it was, as a board does while a host waits
    on it."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.speed: float = inner.speed
        self.until = 0.0
        self._real_time_from: tuple[float, float] | None = None    # (wall, board) s

    def target(self, now_s: float) -> float | None:
        due = self.inner.target(now_s)
        if due is None:
            return None
        if self._real_time_from is not None:
            wall, board = self._real_time_from
            due = min(due, board + time.monotonic() - wall)
        else:
            due = min(due, self.until)
        return due if due > now_s else None

    def real_time(self, board: Any) -> None:
        self._real_time_from = (time.monotonic(), board.time)

    def hold(self, board: Any) -> None:
        self._real_time_from = None
        self.until = board.time


class InputRecord:
    """Writes every byte the board is sent, and every reset, with the board's cycle,
    to ``path`` (JSON lines), so that ``replay`` runs the same board again, bit for bit,
    without the host and its threads."""

    def __init__(self, board: Any, path: Path) -> None:
        self._file = path.open("w")
        self._loop = board.loop
        send, reset = board._send, board._dtr_reset

        def recorded_send(data: bytes) -> None:
            self._file.write(json.dumps({"c": self._loop.cycle, "d": data.hex()}) + "\n")
            send(data)

        def recorded_reset() -> None:
            self._file.write(json.dumps({"c": self._loop.cycle, "reset": True}) + "\n")
            reset()
        board._send, board._dtr_reset = recorded_send, recorded_reset

    def close(self) -> None:
        self._file.close()


def replay(path: Path, seed: int, until_s: float | None = None) -> PortLoop:
    """The board of a soak run with ``--record path`` (gzipped too, ``.gz``), run again
    from its recorded input up to ``until_s`` (its end by default): the same ``PortLoop`` state, its
    output in ``take_output()``. ``wcsim://``'s board is a ``PortLoop`` with a gyro
    seeded by the URL's seed."""
    params = ChairParams()
    loop = PortLoop(Plant(params), Gyro(params, seed, history=GYRO_HISTORY))
    end = None if until_s is None else round(until_s * F_CPU)
    with (gzip.open(path, "rt") if path.suffix == ".gz" else path.open()) as f:
        for line in f:
            entry = json.loads(line)
            if end is not None and entry["c"] > end:
                break
            loop.run_until(entry["c"])
            if entry.get("reset"):
                loop.reset()
            else:
                loop.send(bytes.fromhex(entry["d"]))
    if end is not None:
        loop.run_until(end)
    return loop


class SentLines:
    """Counts the lines the board hands to the link, from the board's own thread;
    ``freeze()`` stops the board where it is (its clock too), so that the host can read
    the last of them before the count is compared."""

    def __init__(self, board: object, port: serial.SerialBase) -> None:
        self.count = 0
        #: lines a board reset cut short: begun (bytes handed to the link) but not ended
        self.cut = 0
        self._open = False
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
        if out:
            self.count += out.count(b"\n")
            self._open = not out.endswith(b"\n")
        return out

    def reset(self) -> None:
        """The board is about to reset: a line it has begun is cut there, and reaches
        the host as a line of its own (the host's decoder splits it from the ``BOOT:``
        that follows), so it counts as sent. On ``simavr://`` the UART hands a line's
        bytes as they leave the wire, so a reset can fall inside one."""
        if self._open:
            self.count += 1
            self.cut += 1
            self._open = False

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


class Pacer:
    """The host's program on the board's clock: ``wait`` lets the board run ``seconds``
    on and returns when it has; ``answering()`` runs the board at real time while the
    host waits for an answer (an ``ACK``, a handshake), and holds it where it got to
    after."""

    def __init__(self, board: Any, speed: float, paced_by_host: bool) -> None:
        self.board = board
        self.speed = speed
        self.clock: HostPacedClock | None = None
        #: (start, end) of each silence the host's program made, in board time
        self.silences: collections.deque[tuple[float, float]] = collections.deque(maxlen=8)
        self._answering_since: float | None = None
        if paced_by_host:
            self.clock = HostPacedClock(board.clock)
            board.clock = self.clock
            # the board thread looks for the next step every 0.2 ms, not every 2 ms:
            # held at each step of the host's, it would otherwise wait 2 ms a step
            board._pause = lambda: 0.0002

    def silent(self, seconds: float) -> None:
        """``wait``, noting the silence (and the 0.3 s after it in which its events
        may still come in) for ``in_silence``."""
        start = self.board.time
        self.silences.append((start, start + seconds + 0.3))
        self.wait(seconds)

    def in_silence(self) -> bool:
        """Whether the board is now within a silence the host's program made."""
        now = self.board.time
        if self._answering_since is not None:
            return True
        return any(a <= now <= b for a, b in self.silences)

    def wait(self, seconds: float) -> None:
        """Sleeps until the board's clock has moved ``seconds`` on."""
        until = self.board.time + seconds
        if self.clock is not None:
            self.clock.until = until
        while self.board.time < until - 1e-6:      # the board stops on a whole cycle
            time.sleep(min(0.1, seconds) / self.speed)

    @contextmanager
    def answering(self) -> Iterator[None]:
        """The host waits for an answer and sends no motion meanwhile: a silence too."""
        start = self.board.time
        self._answering_since = start
        if self.clock is not None:
            self.clock.real_time(self.board)
        try:
            yield
        finally:
            if self.clock is not None:
                self.clock.hold(self.board)
            self._answering_since = None
            self.silences.append((start, self.board.time + 0.3))


def soak(backend: str, hours: float, speed: float, seed: int, record: Path | None = None) -> Report:
    rng = random.Random(seed)
    report = Report(backend, hours, speed, seed)
    url = f"wcsim://?speed={speed:g}&seed={seed}" if backend == "sim" else f"wcavr://?speed={speed:g}"
    port = serial.serial_for_url(url, timeout=0.05)
    board = port.board
    pace = Pacer(board, speed, paced_by_host=backend == "sim")
    recorder = InputRecord(board, record) if record is not None and backend == "sim" else None
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
        if msg.name == "WATCHDOG" and not pace.in_silence():
            report.watchdog_while_driving += 1
            if len(report.event_log) < 50:
                report.event_log.append(f"{board.time:.2f} s: WATCHDOG while driving "
                                        f"(silences {list(pace.silences)[-2:]})")
        if not msg.name.startswith(EXPECTED_EVENTS) and len(report.event_log) < 50:
            report.event_log.append(f"{board.time:.2f} s: {msg.name}")
        on_event(now, msg)
    chair._session._dispatch[Event] = count_event

    chair.on_telemetry(on_tick)
    chair.on_reset(on_reset)
    tracemalloc.start()
    started = time.monotonic()
    try:
        with pace.answering():
            chair.wait_for_handshake(10.0)
            chair.wait_for_neutral(10.0)            # as connect(): it drives after a neutral
        chair.history_limit = 1000
        end = hours * 3600.0
        expect: set[str] = set()
        marks: dict[str, tracemalloc.Snapshot] = {}
        while board.time < end:
            if "start" not in marks and board.time >= 600.0:
                report.memory_start, marks["start"] = _memory()
            if "middle" not in marks and board.time >= end / 2 and "start" in marks:
                report.memory_middle, marks["middle"] = _memory()
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
                pace.silent(rng.uniform(1.0, 3.0))
                continue
            elif kind == "param":
                report.param_changes += 1
                name, value = rng.choice((("max_accel", rng.uniform(1.0, 4.0)),
                                          ("watchdog_ms", float(rng.choice((300, 500, 1000))))))
                with pace.answering():
                    chair.set_param(name, value)
            elif kind == "estop":
                report.estops += 1
                expect.add("ESTOP")
                with pace.answering():
                    chair.estop()
                pace.silent(2.0)
                with pace.answering():
                    chair.reset_estop(timeout=10.0)
                continue
            elif kind == "reset":
                report.board_resets += 1
                expect.update(("BOARD_RESET", "PARAMS_LOADED", "PARAMS_DEFAULT"))
                chair.stop()
                pace.silent(2.0)                            # at rest: the pose is final
                # the host reads every line first: a DTR pulse drops what waits unread
                # (as on a real port), and those lines would be neither read nor lost
                sent.freeze(port, lambda: chair.link_stats.total)
                at_rest = chair.odometry.pose
                before_reset[0] = (at_rest.x, at_rest.y, at_rest.theta)
                sent.reset()
                seen = chair.boots
                board.dtr()
                sent.frozen = False
                with pace.answering():
                    chair.wait_for_boot(seen, 10.0)     # the new board's BOOT read, hello answered
                    chair.wait_for_neutral(10.0)        # the program drives on: a neutral first
                pace.silent(0.5)
                continue
            stop_at = board.time + length
            stall_at = board.time + rng.uniform(1.0, length) if kind == "drive" and rng.random() < 0.2 \
                else math.inf
            while board.time < stop_at:
                try:
                    chair.set_velocity(linear, angular)
                except WcdriveNeutralError:             # a stall's watchdog stop: drive on
                    with pace.answering():              # after a neutral command
                        chair.wait_for_neutral(10.0)
                    continue
                except wcdrive.WcdriveError as exc:
                    report.failures.append(f"{board.time:.1f} s: {exc}")
                    break
                if board.time >= stall_at:                # the host stops sending, then drives on
                    report.stalls += 1
                    # a watchdog stop in the stall: the board refuses the command the host
                    # sends on before it has read of the stop, until a neutral one
                    expect.update(("WATCHDOG", "NOT_NEUTRAL", "NEUTRAL"))
                    stall_at = math.inf
                    pace.silent(rng.uniform(0.2, 1.5))
                    continue
                pace.wait(0.1)
        chair.stop()
        pace.silent(2.0)
        report.memory_end, last = _memory()
        if "start" not in marks:
            report.memory_start = report.memory_end
        for name, into in (("start", report.memory_growth), ("middle", report.memory_growth_late)):
            if name in marks:
                into += _growth(last, marks[name])
        events = list(event_counts) + [e for e in chair.events if e not in event_counts]
        with pace.answering():
            sent.freeze(port, lambda: chair.link_stats.total)
        stats = chair.link_stats
        report.final_truth = board.pose()
    finally:
        tracemalloc.stop()
        chair.close()
        if recorder is not None:
            recorder.close()
    report.wall_s = time.monotonic() - started
    report.sent_lines = sent.count
    report.cut_lines = sent.cut
    report.lines = stats
    for (x, y, _), r in resets:
        jump = ((r.pose[0] - x) ** 2 + (r.pose[1] - y) ** 2) ** 0.5
        report.worst_reset_jump_m = max(report.worst_reset_jump_m, jump)
    allowed = tuple(e for e in EXPECTED_EVENTS if e in expect or e.startswith("PARAMS"))
    report.unexpected_events = sorted({e for e in events if not e.startswith(allowed)})
    _judge(report)
    return report


def _memory() -> tuple[int, tracemalloc.Snapshot]:
    """The memory traced now, after a collection, and a snapshot of where it is."""
    gc.collect()
    return tracemalloc.get_traced_memory()[0], tracemalloc.take_snapshot()


def _growth(now: tracemalloc.Snapshot, then: tracemalloc.Snapshot) -> list[str]:
    """Where the memory grew from ``then`` to ``now``: the 8 largest sites."""
    grown = now.compare_to(then, "lineno")
    return [f"{st.traceback[0].filename}:{st.traceback[0].lineno} "
            f"{st.size_diff / 1e3:+.0f} kB ({st.count_diff:+d} blocks)"
            for st in grown[:8] if st.size_diff > 0]


def _judge(r: Report) -> None:
    since = r.memory_middle or r.memory_start
    growth = r.memory_end - since
    if growth > MEMORY_BOUND:
        r.failures.append(f"host memory grew {growth / 1e3:.0f} kB in the "
                          f"{'second half' if r.memory_middle else 'run after 10 min'} "
                          f"(bound {MEMORY_BOUND / 1e3:.0f} kB)")
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
    ap.add_argument("--record", type=Path, metavar="FILE",
                    help="write the board's input (sim) to FILE for replay()")
    args = ap.parse_args(argv)
    r = soak(args.backend, args.hours, args.speed, args.seed, args.record)
    if args.json:
        print(json.dumps(asdict(r), indent=2))
    else:
        print(f"soak on {r.backend}: {r.hours:g} simulated h at {r.speed:g}x in {r.wall_s:.0f} s wall")
        print(f"host memory after 10 min / half-way / at the end: {r.memory_start / 1e6:.3f} / "
              f"{r.memory_middle / 1e6:.3f} / {r.memory_end / 1e6:.3f} MB "
              f"({(r.memory_end - r.memory_start) / 1e3:+.0f} kB)")
        for site in r.memory_growth:
            print(f"  grew from 10 min at {site}")
        for site in r.memory_growth_late:
            print(f"  grew from half-way at {site}")
        n = r.lines
        print(f"the chair at the end (x, y, heading): {r.final_truth}")
        print(f"lines sent {r.sent_lines} ({r.cut_lines} cut short by a reset): good {n.good}, "
              f"bad CRC {n.bad_crc}, spliced {n.spliced}, lost {n.lost}")
        print(f"ticks {r.ticks}; gaps over {TICK_GAP * 1000:.0f} ms: {len(r.tick_gaps)}")
        print(f"board resets {r.board_resets} (largest odometry jump {r.worst_reset_jump_m * 1000:.2f} mm), "
              f"e-stops {r.estops}, watchdog pauses {r.pauses}, stalls while driving {r.stalls}, "
              f"parameter changes {r.param_changes}")
        print(f"watchdog stops while the host drove, but for its stalls (a starved loop): "
              f"{r.watchdog_while_driving}")
        print(f"unexpected events: {', '.join(r.unexpected_events) or 'none'}")
        for line in r.event_log:
            print(f"  {line}")
        print("checks: " + ("all met" if not r.failures else "FAILED: " + "; ".join(r.failures)))
    return 1 if r.failures else 0


if __name__ == "__main__":
    sys.exit(main())
