"""R2, board to host: the board's v4 lines corrupted on the way, through the host's own
decoder (``wcdrive.protocol.codec.LineDecoder``, as ``Session`` runs it) and its wheel
odometry (``WheelOdometry``), the figures of docs/benchmarks.md's "R2, board to host".

    python benchmarks/board_lines.py [--lines 1000000] [--simavr-seconds 60] [--seed 1]

The lines are what the firmware sent after ``hello:4`` on a random drive (turns,
reversals, stops, ``get:`` requests so that ``ACK``/``PAR`` lines come too): from the
port (``SteppedChair``) for ``--lines``, and from the ELF in simavr (the lock-step
recorder) for ``--simavr-seconds``, that stream replayed under fresh corruption until it
too passes ``--lines``/10. Each line, with probability 0.3, is corrupted one way: 1, 2
or 3 flipped bits; a byte lost; a run of 2 to 40 bytes lost (which joins it to the
next line: a splice, as a full receive buffer makes); or the line lost. Counted:

- *accepted*: a message the decoder let through that the board did not send, in its
  place (0 required): a false ``ACK``, ``ENC`` count, ``TLM`` flag or event;
- the decoder's ``LineStats`` against the lines sent (good + bad CRC + spliced + lost;
  a flip that makes a line end adds one);
- the odometry's end pose from the lines believed against the pose from every line the
  board sent (the largest over the passes). With 0 accepted, the lines believed are a
  subset of those sent, so the odometry is the one a clean loss of the dropped lines
  gives; a dropped ``ENC`` line only delays the next absolute count.

Exits 1 when a corrupted line was accepted.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from wcdrive.boards.port_loop import F_CPU
from wcdrive.host.odometry import WheelOdometry
from wcdrive.protocol.codec import (
    LINE_COUNTER_WRAP,
    Corrupt,
    Feedback,
    LineDecoder,
    LineStats,
    Unknown,
    board_frame,
    encode_cmdvel,
    frame,
    parse_line,
)
from wcdrive.testing.stepped import SteppedChair

CORRUPT_SHARE = 0.3
KINDS = ("flip1", "flip2", "flip3", "byte", "run", "line")


@dataclass
class Figures:
    source: str
    sent: int = 0
    corrupted: int = 0
    accepted: int = 0
    lines: LineStats = field(default_factory=LineStats)
    cuts: int = 0
    passes: int = 0
    pose_vs_all_m: float = 0.0
    seconds: float = 0.0


def port_lines(seconds: float, seed: int) -> list[bytes]:
    """The board's lines (each with its ``\\r\\n``) after hello:4 on a random drive."""
    rng = random.Random(seed)
    chair = SteppedChair(seed=seed)
    loop = chair.loop
    out = bytearray()

    def run(seconds: float) -> None:
        loop.run_until(loop.cycle + round(seconds * F_CPU))
        for _, data in loop.take_output():
            out.extend(data)
    run(0.06)
    loop.send(frame(b"hello:4", 1))
    seq = 2
    t = 0.0
    while t < seconds:
        linear, angular = rng.uniform(-0.3, 1.0), rng.uniform(-0.8, 0.8)
        if rng.random() < 0.15:
            linear = angular = 0.0
        for _ in range(rng.randint(5, 60)):
            body = (encode_cmdvel(linear, angular) if rng.random() < 0.9
                    else b"get:" + rng.choice((b"kp_l", b"max_accel", b"watchdog_ms")))
            loop.send(frame(body, seq))
            seq = seq % 65535 + 1
            run(0.1)
            t += 0.1
    text = bytes(out)
    start = text.index(b"HELLO:4")
    return [line + b"\r\n" for line in text[start:].split(b"\r\n")[:-1]]


def simavr_lines(seconds: float, seed: int) -> list[bytes]:
    """The same kind of drive on the ELF in simavr (lock-step recorder, encoders from a
    smooth trajectory)."""
    import numpy as np

    from wcdrive.hil.lockstep import record
    from wcdrive.hil.traces import Trace
    from wcdrive.plant.encoders import edges_from_trajectory

    rng = random.Random(seed)
    serial = [(0.06, frame(b"hello:4", 1))]
    seq, t = 2, 0.1
    while t < seconds:
        body = (encode_cmdvel(rng.uniform(-0.3, 1.0), rng.uniform(-0.8, 0.8))
                if rng.random() < 0.9 else b"get:kp_l")
        serial.append((t, frame(body, seq)))
        seq += 1
        t += 0.1
    times = np.linspace(0.0, seconds, 200)
    counts = np.cumsum(np.concatenate(([0.5], np.abs(np.diff(np.sin(times))) * 3000.0)))
    encoders = {"left": edges_from_trajectory(times, -counts), "right": edges_from_trajectory(times, counts)}
    rec = record(Trace(duration=seconds, serial=serial, encoders=encoders))
    text = rec.tx
    start = text.index(b"HELLO:4")
    return [line + b"\r\n" for line in text[start:].split(b"\r\n")[:-1]]


def corrupt(line: bytes, kind: str, rng: random.Random) -> bytes:
    body = bytearray(line[:-2])
    if kind.startswith("flip"):
        for p in rng.sample(range(8 * len(body)), int(kind[-1])):
            body[p // 8] ^= 0x80 >> (p % 8)
        return bytes(body) + b"\r\n"
    if kind == "byte":
        del body[rng.randrange(len(body))]
        return bytes(body) + b"\r\n"
    if kind == "run":                        # the run takes the line end: a splice
        at = rng.randrange(len(body))
        return bytes(body[:at])
    return b""


def _odometry(feedback: list[Feedback]) -> tuple[float, float]:
    odo = WheelOdometry()
    est = None
    for k, fb in enumerate(feedback):
        est = odo.update(0.05 * k, fb.count_left, fb.count_right)   # the times do not enter the pose
    return (est.pose.x, est.pose.y) if est is not None else (0.0, 0.0)


def run(source: str, lines: list[bytes], total: int, seed: int) -> Figures:
    """``lines`` replayed under fresh corruption until ``total`` are sent; each pass
    re-framed with a counter that runs on, as the board's would, and its odometry
    compared on its own (a pass starts the counts again)."""
    rng = random.Random(seed)
    f = Figures(source)
    started = time.monotonic()
    decoder = LineDecoder()
    decoder.framed = True
    texts = [line[:-2].rpartition(b"#")[0] for line in lines]
    truth = [parse_line(text) for text in texts]
    counter = 0
    while f.sent < total:
        believed: list[Feedback] = []
        every: list[Feedback] = []
        for text, true in zip(texts, truth, strict=True):
            line = board_frame(text, counter)
            counter = (counter + 1) % LINE_COUNTER_WRAP
            f.sent += 1
            damaged = rng.random() < CORRUPT_SHARE
            data = line
            if damaged:
                f.corrupted += 1
                data = corrupt(line, rng.choice(KINDS), rng)
                f.cuts += max(0, data.count(b"\n") - 1)
            if isinstance(true, Feedback):
                every.append(true)
            for msg in decoder.feed(data):
                if isinstance(msg, (Corrupt, Unknown)):
                    continue
                # What the decoder believes must be this line's message, unchanged (a
                # splice's tail that passed would be another line's).
                if damaged or msg != true:
                    f.accepted += 1
                elif isinstance(msg, Feedback):
                    believed.append(msg)
            if f.sent >= total:
                break
        b, a = _odometry(believed), _odometry(every[:len(every)])
        f.pose_vs_all_m = max(f.pose_vs_all_m, ((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2) ** 0.5)
        f.passes += 1
    f.lines = decoder.stats
    f.seconds = time.monotonic() - started
    return f


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lines", type=int, default=1_000_000)
    ap.add_argument("--port-seconds", type=float, default=300.0)
    ap.add_argument("--simavr-seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    results = [run("port", port_lines(args.port_seconds, args.seed), args.lines, args.seed)]
    if args.simavr_seconds > 0:
        results.append(run("firmware (simavr)", simavr_lines(args.simavr_seconds, args.seed),
                           args.lines // 10, args.seed))
    print("| lines from | sent | corrupted | accepted | good | bad CRC | spliced | lost | "
          "sum - sent (cuts) | passes | pose vs every line (m) | s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|")
    for f in results:
        n = f.lines
        print(f"| {f.source} | {f.sent:,} | {f.corrupted:,} | **{f.accepted}** | {n.good:,} | "
              f"{n.bad_crc:,} | {n.spliced:,} | {n.lost:,} | {n.total - f.sent:+d} ({f.cuts}) | "
              f"{f.passes} | {f.pose_vs_all_m:.2e} | {f.seconds:.1f} |")
    return 1 if any(f.accepted for f in results) else 0


if __name__ == "__main__":
    sys.exit(main())
