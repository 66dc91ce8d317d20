"""The bench tool: a real board on USB (or a stand-in) through its whole cycle.

    wcdrive bench flash  --port /dev/ttyACM0 [--dry-run]
    wcdrive bench run    SCENARIO --port /dev/ttyACM0 [--record run.wcrec.json] [--plot DIR]
                         [--mcap run.mcap | --live]   (ROS 2 messages, wcdrive.ros2)
    wcdrive bench record SCENARIO --port /dev/ttyACM0 --out run.wcrec.json
    wcdrive bench replay run.wcrec.json            # the port must agree, byte for byte
    wcdrive bench plot   run.wcrec.json --out DIR

``--port`` takes what ``wcdrive.connect`` takes: a device path, ``simavr://?realtime=1`` (the
compiled firmware in simavr with the chair behind its pins: what CI uses in place of
a board) or ``sim://``. ``run`` drives a scenario (``wcdrive sim --list``) the way a
host would, in real time, recording every byte both ways from the board's reset;
``record`` is ``run`` with the recording required. ``replay`` then feeds that recording
to the Python port (``wcdrive.replay``) and proves the board and the port agree. Exit
status: 0 agree, 1 mismatch, 2 error, 130 interrupted (Ctrl-C: ``run`` stops the chair
and still writes the recording made so far, marked ``"interrupted": true`` in its meta).
With the wheels on the ground the chair moves: run scenarios with it on blocks.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import wcdrive
from wcdrive.boards.simavr.build import build_dir, firmware_elf
from wcdrive.protocol.codec import ExtendedTelemetry, Feedback, LineDecoder
from wcdrive.replay import main as replay_main
from wcdrive.resources import firmware_dir
from wcdrive.sim import scenario
from wcdrive.transports.recording import Recording


def flash_command(port: str) -> list[str]:
    """The avrdude command that uploads the built firmware's HEX through the Mega's
    stk500v2 bootloader on ``port``."""
    hex_path = build_dir(firmware_dir()) / "final_control.hex"
    return ["avrdude", "-p", "atmega2560", "-c", "wiring", "-P", port, "-b", "115200", "-D",
            "-U", f"flash:w:{hex_path}:i"]


def _flash(args: argparse.Namespace) -> int:
    if "://" in args.port:
        print(f"wcdrive bench flash: {args.port} is not a serial device; avrdude needs a "
              "path such as /dev/ttyACM0")
        return 2
    cmd = flash_command(args.port)
    if not args.dry_run:
        firmware_elf()
    print("$ " + shlex.join(cmd), flush=True)
    if args.dry_run:
        return 0
    return subprocess.call(cmd)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during ``run_scenario``: the chair was stopped and closed; ``recording``
    holds the session up to then."""

    def __init__(self, recording: Recording) -> None:
        super().__init__("interrupted")
        self.recording = recording


def run_scenario(name: str, url: str, *, speed: float = 1.0,
                 announce: Callable[[str], None] | None = None, ros: Any = None) -> Recording:
    """Drives scenario ``name`` on the board at ``url`` and returns the recording;
    ``announce`` gets a line once the chair is connected. Ctrl-C stops the chair and
    raises ``Interrupted`` with the recording so far."""

    sc = scenario.load(name)
    if sc.closed_loop:                          # its commands come from the odometry
        raise scenario.ScenarioError(f"{sc.name} is a closed-loop (path) scenario: wcdrive sim runs "
                                     "those; bench run replays timed segments")
    period = 1.0 / (sc.host_rate_hz * speed)
    recording: Recording | None = None
    try:
        with wcdrive.connect(url, record=True, ros=ros) as chair:   # ros: --mcap/--live sink
            recording = chair.recording
            recording.meta.update({"scenario": sc.name, "url": url, "protocol": chair.protocol_version,
                                   "firmware": chair.firmware, "firmware_version": chair.firmware_version,
                                   "build_id": chair.build_id})
            if announce is not None:
                announce(f"driving {sc.name} on {url} (firmware {chair.firmware} "
                         f"{chair.firmware_version}, build {chair.build_id}; Ctrl-C stops the chair)")
            for segment in sc.segments:
                command = segment.command()
                end = time.monotonic() + segment.duration / speed
                while time.monotonic() < end:
                    if command is not None:
                        chair.send_command(command)
                    time.sleep(period)
            chair.stop()
            time.sleep(sc.settle_s / speed)
    except KeyboardInterrupt as exc:            # leaving the with block stopped the chair
        if recording is None:
            raise
        recording.meta["interrupted"] = True
        raise Interrupted(recording) from exc
    return recording


def _run(args: argparse.Namespace) -> int:
    def announce(text: str) -> None:
        print(f"wcdrive bench {args.bench_command}: {text}", file=sys.stderr, flush=True)

    ros: Any = None
    if args.mcap or args.live:
        from wcdrive import ros2

        if args.live:
            ros = ros2.LiveSink(port=args.live_port)
            announce(f"live: ws://127.0.0.1:{ros.port} (Foxglove)")
        else:
            ros = ros2.McapSink(args.mcap)
    try:
        recording = run_scenario(args.scenario, args.port, speed=args.speed, announce=announce, ros=ros)
    except Interrupted as exc:
        print(f"wcdrive bench {args.bench_command}: interrupted, the chair was stopped", file=sys.stderr)
        if args.record:
            print(f"partial recording: {exc.recording.save(args.record)}", file=sys.stderr)
        return 130
    finally:
        if ros is not None:
            ros.close()                          # closed with the chair too, if it opened
    print(f"recorded {len(recording.sent_bytes)} bytes sent, {len(recording.received_bytes)} received")
    if args.record:
        print(f"recording: {recording.save(args.record)}")
    if args.plot:
        for p in plot(recording, Path(args.plot)):
            print(f"plot: {p}")
    return 0


def _replay(args: argparse.Namespace) -> int:
    return replay_main(args.recording)


def plot(recording: Recording, out: Path) -> list[Path]:
    """Wheel speeds, PWM (signed by DIR) and encoder counts against the board's millis()."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows: list[tuple[float, float, float, int, int]] = []
    feedback = None
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
    for p in plot(Recording.load(args.recording), Path(args.out)):
        print(f"plot: {p}")
    return 0


def add_parser(sub: Any) -> None:
    """``wcdrive bench ...``: adds the subcommand to the CLI's subparsers."""
    bench = sub.add_parser("bench", help="a real board on USB: flash, run, record, replay, plot",
                           description=__doc__.split("\n\n")[0])
    verbs = bench.add_subparsers(dest="bench_command", required=True)
    f = verbs.add_parser("flash", help="build the firmware and upload it with avrdude")
    f.add_argument("--port", default="/dev/ttyACM0", help="the board's serial device")
    f.add_argument("--dry-run", action="store_true", help="print the command only")
    f.set_defaults(func=_flash)
    for verb in ("run", "record"):
        r = verbs.add_parser(verb, help="drive a scenario on the board" + (
            " and record the session" if verb == "record" else " (optionally recording it)"))
        r.add_argument("scenario", help="bundled scenario name or a .toml file")
        r.add_argument("--port", default="/dev/ttyACM0",
                       help="device path, simavr:// or sim:// (what wcdrive.connect takes)")
        if verb == "record":
            r.add_argument("--out", dest="record", required=True, help="the recording (.wcrec.json)")
        else:
            r.add_argument("--record", help="where the recording goes (.wcrec.json)")
        r.add_argument("--plot", help="also write plots to this directory")
        ros_out = r.add_mutually_exclusive_group()
        ros_out.add_argument("--mcap", metavar="FILE", help="also write ROS 2 messages into an MCAP file")
        ros_out.add_argument("--live", action="store_true", help="serve ROS 2 messages to Foxglove")
        r.add_argument("--live-port", type=int, default=8765, help="--live: the port (default 8765)")
        r.add_argument("--speed", type=float, default=1.0,
                       help="scenario time per wall time (only for simulated boards)")
        r.set_defaults(func=_run)
    p = verbs.add_parser("replay", help="replay a recording through the Python port")
    p.add_argument("recording", type=Path)
    p.set_defaults(func=_replay)
    q = verbs.add_parser("plot", help="plot a recording")
    q.add_argument("recording", type=Path)
    q.add_argument("--out", default="wcdrive-out/bench")
    q.set_defaults(func=_plot)
