"""``wcdrive``: the one command line.

    wcdrive --version                                    package and protocol versions, native paths
    wcdrive sim [SCENARIO ...] [--backend port|simavr] [--json] [--out DIR] [--no-plots] [--ekf] [--check]
    wcdrive sim --all --check                            every bundled scenario held to its [expect]
    wcdrive sim --list
    wcdrive verify --traces N --seed S [--elf PATH]      the port against the firmware in simavr
    wcdrive verify --fp N [--seed S]                     binary32 on the AVR against the port, N pairs/op
    wcdrive bench {flash,run,record,replay,plot} ...     a real board on USB
    wcdrive pty [--avr [--realtime] [--bootloader]] [--speed S] [--link PATH]
                                                         a simulated chair on a pty (opening resets it)
    wcdrive pty --eddie [--speed S] [--eol tolerant]           a simulated Eddie board on a pty
    wcdrive can-gateway --chair URL_OR_PATH --interface I --channel C
                                                         a chair's serial port on a CAN bus
    wcdrive ros2 [URL] [--twist] [--no-tf] [--network [--peer HOST]] [--ros-args ...]
                                                         the chair as a ROS 2 node on DDS (docs/ros2.md)
    wcdrive sweep SPEC.toml [--scheduler tcp://HOST:8786 | --workers N | --serial] [--out rows.csv]
                                                         many sim runs on Dask, one row each

Ctrl-C (SIGINT) ends every command cleanly: what it drives is stopped, ports are
closed, and the exit status is 130 with no traceback (``bench run`` keeps the
recording made so far, ``sweep`` the finished rows).

An error prints one line, ``wcdrive <command>: <what went wrong>``, and no traceback
unless ``--debug`` is given (which also logs the ``wcdrive`` loggers at DEBUG); the
exit status tells the kind of failure (``wcdrive.tools.console``: 1 a check failed, 2 bad
arguments or files, 3 connection, 4 timeout, 5 protocol, 6 command refused, 7 build,
70 internal error, 130 interrupted).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import serial

from wcdrive import __version__
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.hil import verify
from wcdrive.host import robots
from wcdrive.protocol.spec import integer
from wcdrive.sim import contract, report, runner, scenario
from wcdrive.tools import bench, console, ros2_node, sweep
from wcdrive.tools.options import add_ros_output
from wcdrive.transports.can_link import CanGateway, open_bus
from wcdrive.transports.pty_bridge import PtyBridge

#: The exit status of a command ended by Ctrl-C (128 + SIGINT), as shells report it.
INTERRUPTED = 130



def version_text() -> str:
    """``wcdrive --version``: the package, the protocol, and how each C helper was had
    (built at install, at first use, or Python and why)."""
    from wcdrive._util import native
    from wcdrive.avr import f32  # noqa: F401  (each loads its C helper, or records why not)
    from wcdrive.firmware import tick_fast  # noqa: F401
    from wcdrive.plant.chair import load_kernel
    from wcdrive.plant.raycast import load_raycast

    load_kernel()
    load_raycast()
    lines = [f"wcdrive {__version__} (protocol v{integer('PROTOCOL_VERSION')})"]
    lines += [f"  {helper}: {how}" for helper, how in sorted(native.paths().items())]
    return "\n".join(lines)


class _Version(argparse.Action):
    """``--version``, computed when asked (it loads the C helpers)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        print(version_text())
        parser.exit()

def _sim(args: argparse.Namespace) -> int:
    if args.list:
        paths = list(scenario.bundled())
        load: Callable[[str], scenario.Scenario] = scenario.load
        if args.robot == "eddie":                      # and Eddie's own (walls)
            eddie_runner = robots.extra("eddie", "runner")
            paths += sorted(eddie_runner.SCENARIOS.glob("*.toml"))
            load = eddie_runner.load
        for path in paths:
            sc = load(str(path))
            loop = "closed loop" if sc.closed_loop else "open loop  "   # open: timed commands
            print(f"{sc.name:28s} {sc.duration:7.1f} s  {loop}  {sc.description}")
        return 0
    names = [p.stem for p in scenario.bundled()] if args.all else (args.scenario or ["square"])
    if args.robot == "eddie":
        if args.all and args.check:          # the Mega's contracts are the Mega's: Eddie's own
            names = _eddie_own()
        return _sim_eddie(args, names)
    status = _sim_mega(args, names)
    if args.all and args.check:              # every bundled scenario: Eddie's own on Eddie too
        eddie = _sim_eddie(args, _eddie_own())
        status = max(status, eddie)
    return status


def _eddie_own() -> list[str]:
    eddie_runner = robots.extra("eddie", "runner")
    return [p.stem for p in sorted(eddie_runner.SCENARIOS.glob("*.toml"))]


def _report_misses(misses: list[contract.Miss]) -> None:
    """``--check``: each miss on a line of its own, on stderr."""
    for miss in misses:
        print(f"wcdrive sim: check failed: {miss}", file=sys.stderr)


def _sim_mega(args: argparse.Namespace, names: list[str]) -> int:
    from wcdrive.plant.params import ChairFileError, load_chair_overrides

    try:                                   # a chair file; a scenario's own [chair] keys win
        chair = load_chair_overrides(args.chair) if args.chair else {}
    except ChairFileError as exc:
        print(f"wcdrive sim: {exc}", file=sys.stderr)
        return 2
    results = []
    misses: list[contract.Miss] = []
    for name in names:
        try:
            sc = scenario.load(name)
        except scenario.ScenarioError as exc:
            print(f"wcdrive sim: {exc}", file=sys.stderr)
            return 2
        if chair:
            sc = dataclasses.replace(sc, chair={**chair, **sc.chair})  # type: ignore[dict-item]
        with console.Bar(sc.name, 1.0, console.progress_enabled(args.json)) as progress:
            result = runner.run(sc, backend=args.backend, seed=args.seed, dt=args.dt, progress=progress,
                                ekf=args.ekf or bool(args.mcap or args.live))
        results.append(result)
        if args.check:
            found = contract.check(sc, result)
            misses += found
            _report_misses(found)
        if args.mcap or args.live:
            _ros_out(args, sc, result, several=len(names) > 1)
        if not args.json:
            print(report.table(result))
        if not args.no_plots:
            paths = report.plots(result, Path(args.out) / sc.name)
            if not args.json:
                print("  plots: " + ", ".join(str(p) for p in paths))
        if not args.json:
            print()
    if args.json:
        print(report.to_json(results))
    failed = [r for r in results if r.firmware_differences]
    if args.check:
        _check_summary(len(results), misses)
    return console.CHECK_FAILED if failed or misses else console.OK


def _check_summary(runs: int, misses: list[contract.Miss]) -> None:
    missed = len({m.scenario for m in misses})
    print(f"wcdrive sim: check: {runs - missed} of {runs} runs kept their [expect]"
          + (f", {missed} missed ({len(misses)} misses)" if misses else ""), file=sys.stderr)


def _ros_out(args: argparse.Namespace, sc: scenario.Scenario, result: runner.SimResult,
             several: bool) -> None:
    """``--mcap`` and ``--live``: the run as ROS 2 messages (``wcdrive.sim.rosout``)."""
    from wcdrive.ros2 import bridge as ros2
    from wcdrive.sim import rosout

    if args.mcap:
        path = Path(args.mcap)
        if several:
            path = path.with_name(f"{path.stem}-{sc.name}{path.suffix or '.mcap'}")
        counts = rosout.write_mcap(result, path, sc.params())
        print(f"  mcap: {path} ({sum(counts.values())} messages on {len(counts)} topics)",
              file=sys.stderr if args.json else sys.stdout)
    if args.live:
        sink = ros2.LiveSink(port=args.live_port)
        print(f"  live: ws://127.0.0.1:{sink.port} (Foxglove), {sc.name} at the board's pace",
              file=sys.stderr, flush=True)
        try:
            rosout.serve(result, sink, sc.params())
        finally:
            sink.close()


def _sim_eddie(args: argparse.Namespace, names: list[str]) -> int:
    eddie_runner = robots.extra("eddie", "runner")
    results = []
    misses: list[contract.Miss] = []
    for name in names:
        try:
            sc = eddie_runner.load(name)
        except scenario.ScenarioError as exc:
            print(f"wcdrive sim: {exc}", file=sys.stderr)
            return 2
        results.append(eddie_runner.run(sc, seed=args.seed))
        if args.check:
            found = eddie_runner.check(sc, results[-1])
            misses += found
            _report_misses(found)
        if not args.json:
            print(eddie_runner.table(results[-1]) + "\n")
    if args.json:
        print(eddie_runner.to_json(results))
    if args.check:
        _check_summary(len(results), misses)
    return console.CHECK_FAILED if misses else console.OK


def _serve(bridge: PtyBridge) -> int:
    """Prints the device path, then serves until Ctrl-C; closes the bridge."""
    print(bridge.path, flush=True)
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        return INTERRUPTED
    finally:
        bridge.close()


def eddie_pty(speed: float = 1.0, seed: int = 0, eol: str = "firmware",
              link: str | None = None) -> PtyBridge:
    """``wcdrive pty --eddie``'s bridge: a simulated Eddie board (``EddieSimBoard``) on a pty."""
    board = robots.extra("eddie", "sim_board")
    return PtyBridge(board(speed=speed, seed=seed, eol=eol).start(), link=link).start()


def _pty(args: argparse.Namespace) -> int:
    if args.eddie:
        bridge = eddie_pty(args.speed, args.seed, args.eol, args.link)
        status = _serve(bridge)
        x, y, heading = bridge.board.pose()     # type: ignore[attr-defined]
        print(f"stopped at {bridge.board.time:.3f} s simulated; ground truth "  # type: ignore[attr-defined]
              f"x={x:.4f} y={y:.4f} heading={heading:.4f}", file=sys.stderr)
        return status
    # Opening the pty resets the board (DTR), as opening a real Mega's port does.
    if args.bootloader:
        from wcdrive.boards.simavr.bootloader_mega import BootloaderBoard

        bl_board = BootloaderBoard(flash_file=args.flash_file, program=args.program,
                                realtime=True, speed=args.speed,
                                plant=not args.no_plant)
        bridge = PtyBridge(bl_board, link=args.link, on_open=bl_board.dtr).start()
        bl_board.start()
        status = _serve(bridge)
        print(f"stopped at {bl_board.mega.time:.3f} s simulated", file=sys.stderr)
        return status
    if args.avr:
        from wcdrive.boards.simavr.mega_board import MegaBoard

        board = MegaBoard(args.elf, realtime=args.realtime, plant=not args.no_plant)
        bridge = PtyBridge(board, link=args.link, on_open=board.dtr).start()
        board.start()
        status = _serve(bridge)
        print(f"stopped at {board.mega.time:.3f} s simulated", file=sys.stderr)
        return status
    sim = SimulatedBoard(speed=args.speed, seed=args.seed)
    return _serve(PtyBridge(sim.start(), link=args.link, on_open=sim.dtr).start())


def _can_gateway(args: argparse.Namespace) -> int:
    port = serial.serial_for_url(args.chair, 115200, timeout=0.1)
    gateway = CanGateway(open_bus(args.interface, args.channel), port).start()
    print(f"{args.chair} <-> CAN {args.interface}/{args.channel} (Ctrl-C to stop)", flush=True)
    end = time.monotonic() + args.seconds if args.seconds else None
    try:
        while end is None or time.monotonic() < end:
            time.sleep(0.1)
    except KeyboardInterrupt:
        return INTERRUPTED
    finally:
        gateway.close()
        port.close()
    return 0


def _sweep(args: argparse.Namespace) -> int:
    spec = sweep.load_spec(args.spec)
    points = sweep.expand(spec)
    out = Path(args.out)
    if args.serial:
        rows = sweep.run_serial(points)
    else:
        rows = sweep.run_dask(points, scheduler=args.scheduler, workers=args.workers)
    start = time.monotonic()
    with console.Bar("sweep", len(points), console.progress_enabled(args.json)) as bar:
        done, interrupted = sweep.collect(rows, on_row=lambda _: bar.advance())
    elapsed = time.monotonic() - start
    if done:
        sweep.write(done, out)
    failed = [r for r in done if r.get("error")]
    summary = {"runs": len(points), "finished": len(done), "failed": len(failed),
               "seconds": round(elapsed, 3), "runs_per_s": round(sweep.throughput(done, elapsed), 3),
               "out": str(out) if done else None, "interrupted": interrupted}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{len(done)} of {len(points)} runs in {elapsed:.1f} s "
              f"({summary['runs_per_s']} runs/s), {len(failed)} failed" + (f" -> {out}" if done else ""))
        for row in failed[:5]:
            print(f"  run {row['run']} ({row['scenario']}, seed {row['seed']}): {row['error']}",
                  file=sys.stderr)
    if interrupted:
        print(f"wcdrive sweep: interrupted; kept the {len(done)} finished rows", file=sys.stderr)
        return console.INTERRUPTED
    return console.CHECK_FAILED if failed else console.OK


def parser() -> argparse.ArgumentParser:
    """The whole command line."""
    top = argparse.ArgumentParser(prog="wcdrive", description="wcdrive: the wheelchair, simulated or real.")
    top.add_argument("--version", action=_Version, nargs=0,
                     help="the package and protocol versions, and which paths run in C")
    top.add_argument("--debug", action="store_true",
                     help="show tracebacks and log the wcdrive loggers at DEBUG")
    sub = top.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("sim", help="drive a simulated chair through a scenario")
    sim.add_argument("scenario", nargs="*", help="bundled scenario name or a .toml file (default: square)")
    sim.add_argument("--all", action="store_true", help="run every bundled scenario")
    sim.add_argument("--list", action="store_true", help="list the bundled scenarios")
    sim.add_argument("--robot", choices=("mega", "eddie"), default="mega",
                     help="the Mega chair (default) or the simulated Parallax Eddie (docs/eddie.md)")
    sim.add_argument("--backend", choices=("port", "simavr"), default="port",
                     help="the Python port (default) or the compiled firmware in simavr")
    sim.add_argument("--json", action="store_true", help="print the metrics as JSON")
    sim.add_argument("--check", action="store_true",
                     help="hold each run to its scenario's [expect] table (wcdrive.sim.expect): each miss "
                          "on stderr, exit 1 if any; with --all, Eddie's own scenarios run on Eddie too")
    sim.add_argument("--out", default="wcdrive-out", help="where the plots go (default: wcdrive-out/)")
    sim.add_argument("--no-plots", action="store_true", help="write no PNG plots")
    sim.add_argument("--seed", type=int, default=0, help="gyro noise seed")
    sim.add_argument("--dt", type=float, default=0.001, help="physics step in s (default 0.001)")
    sim.add_argument("--chair", help="a chair file (wcdrive bench identify --out): its [chair] table "
                     "for the plant; a scenario's own [chair] keys win")
    sim.add_argument("--ekf", action="store_true",
                     help="also run the host's two EKFs (docs/odometry.md) on the 400 Hz gyro and "
                          "report odom_ekf_*: about 25 times slower (--mcap and --live imply it)")
    add_ros_output(sim, exclusive=False,
                   mcap_help="write the run as ROS 2 messages into an MCAP file (with several "
                             "scenarios: FILE-<name>.mcap)",
                   live_help="serve the run's ROS 2 messages to Foxglove (WebSocket), paced by "
                             "the board's clock")
    sim.set_defaults(func=_sim)

    ver = sub.add_parser("verify", help="differential check of the port against the firmware in simavr",
                         description=(verify.__doc__ or "").split("\n\n")[0])
    verify.add_arguments(ver)
    ver.set_defaults(func=verify.run)

    bench.add_parser(sub)

    pty = sub.add_parser("pty", help="a simulated chair as a pseudo-terminal for outside programs")
    pty.add_argument("--eddie", action="store_true",
                     help="a simulated Parallax Eddie control board instead (docs/eddie.md)")
    pty.add_argument("--eol", choices=("firmware", "tolerant"), default="firmware",
                     help="--eddie: LF is stored as the firmware does, or ends a line too")
    pty.add_argument("--avr", action="store_true",
                     help="the compiled firmware in simavr (default: the Python port)")
    pty.add_argument("--speed", type=float, default=1.0, help="simulated time per wall time (the port)")
    pty.add_argument("--realtime", action="store_true",
                     help="--avr: pace to the wall clock (default: as fast as simavr runs)")
    pty.add_argument("--link", help="also make this symlink to the pty, e.g. /tmp/ttyWC0")
    pty.add_argument("--seed", type=int, default=0, help="gyro noise seed")
    pty.add_argument("--elf", help="--avr: firmware ELF (default: build the bundled firmware)")
    pty.add_argument("--no-plant", action="store_true", help="--avr: leave the encoder pins still")
    pty.add_argument("--bootloader", action="store_true",
                     help="--avr: a Mega with the stk500v2 bootloader and no program until avrdude "
                          "writes one (real time while the bootloader runs, then --speed times real time)")
    pty.add_argument("--flash-file", help="--bootloader: keep the flash in this file across runs")
    pty.add_argument("--program", help="--bootloader: a HEX already in flash at start")
    pty.set_defaults(func=_pty)

    gw = sub.add_parser("can-gateway", help="put a chair's serial port on a CAN bus (protocol/CAN.md)")
    gw.add_argument("--chair", required=True,
                    help="the chair's port: /dev/ttyACM0, or wcsim://?speed=1 for the simulated one")
    gw.add_argument("--interface", default="socketcan", help="python-can interface (default socketcan)")
    gw.add_argument("--channel", default="can0", help="CAN channel (default can0)")
    gw.add_argument("--seconds", type=float, help="stop after this long (default: run until Ctrl-C)")
    gw.set_defaults(func=_can_gateway)

    ros2_node.add_parser(sub)

    sw = sub.add_parser("sweep", help="many sim runs (scenarios x parameters x seeds) on Dask",
                        description=(sweep.__doc__ or "").split("\n\n")[0])
    sw.add_argument("spec", help="the sweep's TOML spec (see wcdrive.tools.sweep)")
    sw.add_argument("--scheduler", help="an existing Dask scheduler, tcp://HOST:8786 "
                                        "(default: a LocalCluster here)")
    sw.add_argument("--workers", type=int, help="LocalCluster worker processes (default: one per core)")
    sw.add_argument("--serial", action="store_true", help="run in this process, without Dask")
    sw.add_argument("--out", default="wcdrive-out/sweep.csv",
                    help="rows as .csv or .parquet (default wcdrive-out/sweep.csv)")
    sw.add_argument("--json", action="store_true", help="print the summary as JSON (and no progress bar)")
    sw.set_defaults(func=_sweep)
    return top


def main(argv: list[str] | None = None) -> int:
    """The ``wcdrive`` command; returns the exit status (module docstring: one per kind
    of failure, 130 after Ctrl-C); an error is one line on stderr, with the traceback
    only under ``--debug``."""
    args = parser().parse_args(argv)
    console.setup_logging(args.debug)
    try:
        status: int = args.func(args)
    except BrokenPipeError:
        # the reader of our output stopped (| head): not an error; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return console.OK
    except (KeyboardInterrupt, Exception) as exc:
        print(console.error_line(args.command, exc), file=sys.stderr)
        if args.debug and not isinstance(exc, KeyboardInterrupt):
            traceback.print_exc()
        return console.exit_code(exc)
    return status
