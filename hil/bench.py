"""The bench tool: a real board on USB (or a stand-in) through its whole cycle.

    python -m hil.bench flash  --port /dev/ttyACM0 [--dry-run]
    python -m hil.bench run    SCENARIO --port /dev/ttyACM0 --record run.wcrec.json [--plot DIR]
    python -m hil.bench replay run.wcrec.json            # the port must agree, byte for byte
    python -m hil.bench plot   run.wcrec.json --out DIR

``--port`` takes what ``wcdrive.connect`` takes: a device path, ``simavr://?realtime=1`` (the
compiled firmware in simavr with the chair behind its pins: what CI uses in place of
a board) or ``sim://``. ``run`` drives a scenario (``wcdrive sim --list``) the way a
host would, in real time, recording every byte both ways from the board's reset;
``replay`` then feeds that recording to the Python port (``wcdrive.replay``) and
proves the board and the port agree. Exit status: 0 agree, 1 mismatch, 2 error.
With the wheels on the ground the chair moves: run scenarios with it on blocks.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parents[1] / "firmware" / "final_control"


def flash_command(port: str) -> list[str]:
    return ["make", "-C", str(FIRMWARE_DIR), "upload", f"PORT={port}"]


def _flash(args: argparse.Namespace) -> int:
    cmd = flash_command(args.port)
    print("$ " + shlex.join(cmd), flush=True)
    if args.dry_run:
        return 0
    return subprocess.call(cmd)


def run_scenario(name: str, url: str, *, speed: float = 1.0):
    """Drives scenario ``name`` on the board at ``url`` and returns the recording."""
    import wcdrive
    from wcdrive.sim import scenario

    sc = scenario.load(name)
    period = 1.0 / (sc.host_rate_hz * speed)
    with wcdrive.connect(url, record=True) as chair:
        recording = chair.recording
        recording.meta.update({"scenario": sc.name, "url": url, "protocol": chair.protocol_version,
                               "firmware": chair.firmware})
        for segment in sc.segments:
            command = segment.command()
            end = time.monotonic() + segment.duration / speed
            while time.monotonic() < end:
                if command is not None:
                    chair.send_command(command)
                time.sleep(period)
        chair.stop()
        time.sleep(sc.settle_s / speed)
    return recording


def _run(args: argparse.Namespace) -> int:
    recording = run_scenario(args.scenario, args.port, speed=args.speed)
    path = recording.save(args.record)
    print(f"recorded {len(recording.sent_bytes)} bytes sent, {len(recording.received_bytes)} "
          f"received: {path}")
    if args.plot:
        for p in plot(recording, Path(args.plot)):
            print(f"plot: {p}")
    return 0


def _replay(args: argparse.Namespace) -> int:
    from wcdrive.replay import main

    return main([str(args.recording)])


def plot(recording, out: Path) -> list[Path]:
    """Wheel speeds, PWM (signed by DIR) and encoder counts against the board's millis()."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wcdrive.codec import ExtendedTelemetry, Feedback, LineDecoder

    rows, feedback = [], None
    for msg in LineDecoder().feed(recording.received_bytes):
        if isinstance(msg, Feedback):
            feedback = msg
        elif isinstance(msg, ExtendedTelemetry) and feedback is not None:
            rows.append((msg.millis / 1000, feedback.vel_left, feedback.vel_right,
                         msg.pwm_left * (1 if msg.dir_left else -1),
                         msg.pwm_right * (1 if msg.dir_right else -1)))
            feedback = None
    out.mkdir(parents=True, exist_ok=True)
    if not rows:
        raise ValueError("no feedback with TLM lines in the recording (a v1 board?)")
    t, vl, vr, pl, pr = zip(*rows, strict=True)
    fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    a1.plot(t, vl, label="left")
    a1.plot(t, vr, label="right")
    a1.set_ylabel("wheel speed (rad/s)")
    a1.legend()
    a2.plot(t, pl, label="left")
    a2.plot(t, pr, label="right")
    a2.set_ylabel("PWM duty (signed by DIR)")
    a2.set_xlabel("board millis() (s)")
    a2.legend()
    fig.suptitle(str(recording.meta.get("scenario", "recording")))
    path = out / "bench.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return [path]


def _plot(args: argparse.Namespace) -> int:
    from wcdrive.recording import Recording

    for p in plot(Recording.load(args.recording), Path(args.out)):
        print(f"plot: {p}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil.bench", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    f = sub.add_parser("flash", help="build the firmware and upload it with avrdude")
    f.add_argument("--port", default="/dev/ttyACM0")
    f.add_argument("--dry-run", action="store_true", help="print the command only")
    f.set_defaults(func=_flash)
    r = sub.add_parser("run", help="drive a scenario on the board and record the session")
    r.add_argument("scenario")
    r.add_argument("--port", default="/dev/ttyACM0", help="device path, simavr:// or sim://")
    r.add_argument("--record", required=True, help="where the recording goes (.wcrec.json)")
    r.add_argument("--plot", help="also write plots to this directory")
    r.add_argument("--speed", type=float, default=1.0,
                   help="scenario time per wall time (only for simulated boards)")
    r.set_defaults(func=_run)
    p = sub.add_parser("replay", help="replay a recording through the Python port")
    p.add_argument("recording", type=Path)
    p.set_defaults(func=_replay)
    q = sub.add_parser("plot", help="plot a recording")
    q.add_argument("recording", type=Path)
    q.add_argument("--out", default="wcdrive-out/bench")
    q.set_defaults(func=_plot)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
