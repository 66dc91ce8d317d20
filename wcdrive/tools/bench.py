"""The bench tool: a real board on USB (or a stand-in) through its whole cycle.

    wcdrive bench flash  --port /dev/ttyACM0 [--hex H] [--no-check] [--dry-run]
    wcdrive bench run    SCENARIO --port /dev/ttyACM0 [--record run.wcrec.json] [--plot DIR]
                         [--mcap run.mcap | --live]   (ROS 2 messages, wcdrive.ros2.bridge)
    wcdrive bench record SCENARIO --port /dev/ttyACM0 --out run.wcrec.json
    wcdrive bench replay run.wcrec.json            # the port must agree, byte for byte
    wcdrive bench replay run.wcrec.json --plant chair.toml   # how well that plant predicts it
    wcdrive bench identify blocks.wcrec.json floor.wcrec.json --out chair.toml
    wcdrive bench plot   run.wcrec.json --out DIR

``--port`` takes what ``wcdrive.connect`` takes: a device path, ``simavr://`` (the
compiled firmware in simavr with the chair behind its pins: what CI uses in place of
a board) or ``sim://``. ``run`` drives a scenario (``wcdrive sim --list``) the way a
host would, in real time, recording every byte both ways from the board's reset;
``record`` is ``run`` with the recording required. ``replay`` then feeds that recording
to the Python port (``wcdrive.tools.replay``) and proves the board and the port agree. Exit
status: 0 agree, 1 mismatch, 2 error, 130 interrupted (Ctrl-C: ``run`` stops the chair
and still writes the recording made so far, marked ``"interrupted": true`` and
``"partial": true`` in its meta).
With the wheels on the ground the chair moves: run scenarios with it on blocks.
``run`` and ``record`` ask "wheels off the ground?" first unless given ``--yes`` (a
simulated ``sim://``/``simavr://`` board is not asked about), and show the
scenario's progress (tqdm) on a terminal. ``flash`` checks the port and the HEX
before avrdude runs, stops avrdude when no bootloader answers, and reads the board's
``hello`` afterwards to check that its build id is the HEX's.
"""

from __future__ import annotations

import argparse
import os
import select
import shlex
import shutil
import stat
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import wcdrive
from wcdrive._util.resources import firmware_dir
from wcdrive.boards.simavr.build import build_dir, firmware_elf
from wcdrive.errors import WcdriveError, WcdriveNeutralError
from wcdrive.host.wheelchair import Wheelchair
from wcdrive.protocol.codec import ExtendedTelemetry, Feedback, Hello, LineDecoder, parse_line
from wcdrive.sim import scenario
from wcdrive.tools.options import add_ros_output
from wcdrive.tools.replay import main as replay_main
from wcdrive.transports.recording import Recording


def flash_command(port: str, hex_path: str | Path | None = None) -> list[str]:
    """The avrdude command that uploads a HEX (default: the built firmware's) through
    the Mega's stk500v2 bootloader on ``port``."""
    hex_path = hex_path or build_dir(firmware_dir()) / "final_control.hex"
    return ["avrdude", "-p", "atmega2560", "-c", "wiring", "-P", port, "-b", "115200", "-D",
            "-U", f"flash:w:{hex_path}:i"]


class FlashError(WcdriveError):
    """``bench flash`` could not flash the board; the message says why and what to do."""


#: The ATmega2560's interrupt vectors (a ``jmp`` each, 4 bytes) and, for the message,
#: other chips' counts.
MEGA2560_VECTORS = 57
_VECTOR_CHIPS = {26: "an ATmega328P/168 (Uno, Nano)", 43: "an ATmega32U4 (Leonardo)",
                 35: "an ATmega644/1284", 57: "an ATmega2560"}


def check_hex(hex_path: Path) -> dict[int, bytes]:
    """The HEX's data, or ``FlashError`` when it is not for an ATmega2560 below its
    bootloader: the vector table (57 ``jmp``s from address 0) tells the chip."""
    from wcdrive.boards.simavr.bootloader_mega import BOOT_START, HexError, parse_ihex

    try:
        runs = parse_ihex(hex_path.read_text())
    except (OSError, UnicodeDecodeError, HexError) as exc:
        raise FlashError(f"cannot read {hex_path} as Intel HEX: {exc}") from None
    if not runs or min(runs) != 0:
        raise FlashError(f"{hex_path} has no program at address 0 (no vector table)")
    image = runs[0]
    vectors = 0
    while vectors * 4 + 2 <= len(image) and image[vectors * 4 + 1] == 0x94 and \
            image[vectors * 4] & 0x0E == 0x0C:        # jmp: 1001 010k kkkk 110k
        vectors += 1
    if vectors != MEGA2560_VECTORS:
        chip = _VECTOR_CHIPS.get(vectors, "another chip")
        raise FlashError(f"{hex_path} is built for {chip}: its vector table has {vectors} "
                         f"jmp entries where an ATmega2560 has {MEGA2560_VECTORS}; build it "
                         "with -mmcu=atmega2560 (refusing to flash it)")
    end = max(start + len(data) for start, data in runs.items())
    if end > BOOT_START:
        raise FlashError(f"{hex_path} reaches {end:#x}, into the bootloader (from {BOOT_START:#x})")
    return runs


def _holders(device: str) -> list[str]:
    """Other processes that have ``device`` open (from /proc), as "pid (command)"."""
    target = os.path.realpath(device)
    out: list[str] = []
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        pid = fd_dir.parent.name
        if int(pid) == os.getpid():
            continue
        try:
            if any(os.path.realpath(fd) == target for fd in fd_dir.iterdir()):
                cmd = (fd_dir.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                out.append(f"{pid} ({cmd.strip()[:60]})")
        except OSError:
            continue
    return out


def check_port(port: str) -> None:
    """``FlashError`` unless ``port`` is a serial device that exists and no other
    program has open. Does not open it (opening resets a Mega)."""
    if "://" in port:
        raise FlashError(f"{port} is a URL, not a serial device: avrdude needs the board's device "
                         "path, such as /dev/ttyACM0 (for the simulated stand-in: wcdrive pty --avr "
                         "--bootloader, then its path)")
    if not os.path.exists(port):
        raise FlashError(f"no board at {port}: the device does not exist (is the Mega plugged in? "
                         "see ls /dev/ttyACM* /dev/ttyUSB*)")
    if not stat.S_ISCHR(os.stat(port).st_mode):
        raise FlashError(f"{port} is not a serial device (not a character device)")
    try:
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise FlashError(f"cannot open {port}: {exc.strerror} (permission: the dialout group?)") from None
    try:
        if not os.isatty(fd):
            raise FlashError(f"{port} is not a serial device (not a terminal)")
    finally:
        os.close(fd)
    holders = _holders(port)
    if holders:
        raise FlashError(f"{port} is busy: open in {', '.join(holders)}; close that program first")


def read_hello(port: str, timeout: float = 6.0) -> str:
    """Opens ``port`` (the board resets), waits for its boot, says ``hello`` and returns
    the ``HELLO:`` line, or "" when none came within ``timeout`` s."""
    import serial

    deadline = time.monotonic() + timeout
    with serial.Serial(port, 115200, timeout=0.05) as link:
        seen = b""
        asked_at = 0.0
        while time.monotonic() < deadline:
            seen += link.read(256)
            for line in seen.split(b"\n"):
                if line.startswith(b"HELLO:"):
                    return line.decode(errors="replace").strip()
            if (b"BOOT:" in seen or b"ENC:" in seen) and time.monotonic() - asked_at > 0.5:
                link.write(b"hello\n")          # unframed: a board answers it before strict mode
                asked_at = time.monotonic()
    return ""


def flash(port: str, hex_path: str | Path | None = None, *, check: bool = True,
          timeout: float = 120.0, stall: float = 10.0, sync: float = 8.0,
          log: Callable[[str], None] = lambda text: print(text, file=sys.stderr, flush=True),
          progress: Callable[[str], None] | None = None) -> str:
    """Flashes ``hex_path`` (default: the firmware, built if needed) to the Mega on
    ``port`` with avrdude, then (``check``) reads its ``hello`` and checks that the
    build id is the HEX's. Returns the HELLO line ("" unchecked). Raises ``FlashError``
    within seconds on a URL, a missing or busy device or a HEX for another chip, and
    when no bootloader answers within ``sync`` s (avrdude has not read the
    signature), when avrdude prints nothing for ``stall`` s, or runs longer than
    ``timeout`` s. ``progress`` gets avrdude's output as it comes."""
    t0 = time.monotonic()
    check_port(port)
    if hex_path is None:
        hex_path = firmware_elf().with_suffix(".hex")
        log(f"built {hex_path} ({time.monotonic() - t0:.1f} s)")
    hex_path = Path(hex_path)
    runs = check_hex(hex_path)
    if shutil.which("avrdude") is None:
        raise FlashError("avrdude is missing: apt-get install avrdude")
    cmd = flash_command(port, hex_path)
    log("$ " + shlex.join(cmd))
    t1 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    assert proc.stdout is not None
    output = bytearray()
    last = time.monotonic()
    try:
        while True:
            ready, _, _ = select.select([proc.stdout], [], [], 0.2)
            if ready:
                chunk = os.read(proc.stdout.fileno(), 4096)
                if not chunk:
                    break
                output += chunk
                last = time.monotonic()
                if progress is not None:
                    progress(chunk.decode(errors="replace"))
            now = time.monotonic()
            if b"device signature" not in output and now - t1 > sync:
                raise FlashError(f"no bootloader answered on {port} within {sync:.0f} s (no board "
                                 "there, or not an Arduino Mega 2560 with its bootloader?)")
            if now - last > stall:
                raise FlashError(f"avrdude made no progress for {stall:.0f} s: no bootloader answers on "
                                 f"{port} (is it an Arduino Mega 2560? try its reset button)")
            if now - t1 > timeout:
                raise FlashError(f"avrdude took longer than {timeout:.0f} s on {port}; stopped it")
        status = proc.wait(timeout=5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = output.decode(errors="replace")
    if status != 0:
        tail = "\n".join([line for line in text.splitlines() if "TIOCMGET" not in line][-6:])
        raise FlashError(f"avrdude failed (exit {status}) on {port}:\n{tail}")
    log(f"flashed {hex_path.name} in {time.monotonic() - t1:.1f} s")
    if not check:
        return ""
    t2 = time.monotonic()
    hello = read_hello(port)
    if not hello:
        raise FlashError(f"the board on {port} did not answer hello within 6 s after flashing "
                         "(not final_control? --no-check skips this)")
    build = check_build_id(hello, runs, hex_path)
    log(f"{hello}: build {build} is the HEX's ({time.monotonic() - t2:.1f} s)")
    return hello


def check_build_id(hello: str, runs: dict[int, bytes], hex_path: Path) -> str:
    """The build id of a ``HELLO:`` line, or ``FlashError`` when that id (a string the
    sketch keeps in flash) is not in the HEX's data."""
    msg = parse_line(hello.encode())
    build = msg.build_id if isinstance(msg, Hello) else ""
    data = b"".join(runs.values())
    if len(build) != 8 or (build.encode() + b"\0") not in data:
        raise FlashError(f"the board says build {build} ({hello}), which is not in {hex_path.name}: "
                         "the flash did not take")
    return build


def _to_stderr(text: str) -> None:
    sys.stderr.write(text)
    sys.stderr.flush()


def _flash(args: argparse.Namespace) -> int:
    if args.dry_run:
        if "://" in args.port:
            check_port(args.port)
        print("$ " + shlex.join(flash_command(args.port, args.hex)), flush=True)
        return 0
    hello = flash(args.port, args.hex, check=not args.no_check, timeout=args.timeout,
                  progress=_to_stderr)
    print(hello or "flashed (unchecked)")
    return 0


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during ``run_scenario``: the chair was stopped and closed; ``recording``
    holds the session up to then."""

    def __init__(self, recording: Recording) -> None:
        super().__init__("interrupted")
        self.recording = recording


def run_scenario(name: str, url: str, *, speed: float = 1.0,
                 announce: Callable[[str], None] | None = None, progress: bool = False,
                 ros: Any = None) -> Recording:
    """Drives scenario ``name`` on the board at ``url`` and returns the recording (the
    scenario's ``[params]`` set first, in the board's RAM only: its next reset forgets
    them); ``announce`` gets a line once the chair is connected; ``progress`` draws a tqdm bar
    of scenario time on stderr (on a terminal). Ctrl-C stops the chair and raises
    ``Interrupted`` with the recording so far, marked ``"partial": true``."""
    from tqdm import tqdm

    sc = scenario.load(name)
    if sc.closed_loop:                          # its commands come from the odometry
        raise scenario.ScenarioError(f"{sc.name} is a closed-loop (path) scenario: wcdrive sim runs "
                                     "those; bench run replays timed segments")
    period = 1.0 / (sc.host_rate_hz * speed)
    recording: Recording | None = None
    try:
        with wcdrive.connect(url, record=True, ros=ros) as chair:   # ros: --mcap/--live sink
            if not isinstance(chair, Wheelchair):       # the scenario's lines are the chair's
                raise scenario.ScenarioError(f"bench run replays the wheelchair's commands; {url} is "
                                             f"a {type(chair).__name__}")
            recording = chair.recording
            recording.meta.update({"scenario": sc.name, "url": url, "protocol": chair.protocol_version,
                                   "firmware": chair.firmware, "firmware_version": chair.firmware_version,
                                   "build_id": chair.build_id})
            if sc.board_params:                             # [params], as wcdrive sim sets them
                for name, value in sc.board_params.items():
                    chair.set_param(name, value)
                recording.meta["params"] = dict(sc.board_params)
            if announce is not None:
                announce(f"driving {sc.name} on {url} (firmware {chair.firmware} "
                         f"{chair.firmware_version}, build {chair.build_id}; Ctrl-C stops the chair)")
            refused = 0
            with tqdm(total=round(sc.duration, 1), unit="s", desc=sc.name, disable=None if progress else True,
                      bar_format="{desc}: {bar} {n:.1f}/{total:.1f} s") as bar:
                for segment in sc.segments:
                    command = segment.command()
                    end = time.monotonic() + segment.duration / speed
                    while time.monotonic() < end:
                        if command is not None:
                            try:
                                chair.send_command(command)
                            except WcdriveNeutralError:     # after a reset mid-run, as wcdrive
                                refused += 1                # sim's host: refused, not sent
                                recording.meta["refused_neutral"] = refused
                        time.sleep(period)
                        bar.update(min(period * speed, bar.total - bar.n))
            chair.stop()
            time.sleep(sc.settle_s / speed)
    except KeyboardInterrupt as exc:            # leaving the with block stopped the chair
        if recording is None:
            raise
        recording.meta["interrupted"] = True
        recording.meta["partial"] = True
        raise Interrupted(recording) from exc
    return recording


#: Schemes of boards with no motors behind them: ``bench run`` does not ask about wheels.
SIMULATED_SCHEMES = ("sim://", "simavr://", "wcsim://", "wcavr://")


def wheels_off_the_ground(port: str, ask: Callable[[str], str] | None = None) -> bool:
    """Asks whether the chair on ``port`` is on blocks; True for "y"/"yes". A
    simulated board (``SIMULATED_SCHEMES``) is not asked about. No answer (no
    terminal) is a no."""
    if port.startswith(SIMULATED_SCHEMES):
        return True
    try:
        answer = (ask or input)(f"The chair on {port} will move. Are its wheels off the ground? [y/N] ")
    except EOFError:
        return False
    return answer.strip().lower() in ("y", "yes")


def _run(args: argparse.Namespace) -> int:
    def announce(text: str) -> None:
        print(f"wcdrive bench {args.bench_command}: {text}", file=sys.stderr, flush=True)

    if not args.yes and not wheels_off_the_ground(args.port):
        print(f"wcdrive bench {args.bench_command}: not started; put the chair on blocks, or pass --yes",
              file=sys.stderr)
        return 2
    ros: Any = None
    if args.mcap or args.live:
        from wcdrive.ros2 import bridge as ros2

        if args.live:
            ros = ros2.LiveSink(port=args.live_port)
            announce(f"live: ws://127.0.0.1:{ros.port} (Foxglove)")
        else:
            ros = ros2.McapSink(args.mcap)
    try:
        recording = run_scenario(args.scenario, args.port, speed=args.speed, announce=announce,
                                 progress=True, ros=ros)
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
    if args.plant is not None:
        from wcdrive.tools.identify import prediction_main

        return prediction_main(args.recording, args.plant, True if args.blocks else None)
    return replay_main(args.recording)


def _identify(args: argparse.Namespace) -> int:
    from wcdrive.tools.identify import identify_main

    return identify_main(args)


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
    f.add_argument("--hex", help="the HEX to upload (default: the firmware, built if needed)")
    f.add_argument("--no-check", action="store_true",
                   help="do not read hello and compare the build id afterwards (another program)")
    f.add_argument("--timeout", type=float, default=120.0, help="stop avrdude after this long (s)")
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
        r.add_argument("--yes", action="store_true",
                       help="do not ask whether the wheels are off the ground")
        add_ros_output(r, exclusive=True, mcap_help="also write ROS 2 messages into an MCAP file",
                       live_help="serve ROS 2 messages to Foxglove")
        r.add_argument("--speed", type=float, default=1.0,
                       help="scenario time per wall time (only for simulated boards)")
        r.set_defaults(func=_run)
    p = verbs.add_parser("replay", help="replay a recording through the Python port (--plant: "
                         "how well a chair file's plant predicts its wheels)")
    p.add_argument("recording", type=Path)
    p.add_argument("--plant", type=Path, help="a chair file (bench identify --out): re-simulate the "
                   "recording's wheels with it and with the default plant, and print both errors")
    p.add_argument("--blocks", action="store_true",
                   help="with --plant: the recording was made on blocks (default: its scenario's name says)")
    p.set_defaults(func=_replay)
    i = verbs.add_parser("identify", help="fit the plant's figures to recordings; write a chair file",
                         description="Fits the chair's motor constant, wheel inertia, current limit, "
                         "mass and rolling resistance to recordings of ident_blocks (on blocks) and "
                         "ident_floor (on the floor); docs/bench.md.")
    i.add_argument("recordings", type=Path, nargs="+", help="bench recordings (.wcrec.json)")
    i.add_argument("--out", type=Path, help="write the fitted [chair] table here (chair.toml)")
    i.add_argument("--start", type=Path,
                   help="a chair file to start from: its figures are held where not fitted "
                        "(a measured armature_resistance or battery_voltage, say)")
    i.add_argument("--blocks", type=Path, action="append",
                   help="this recording was made on blocks (repeatable; default: the scenario's name)")
    i.add_argument("--floor", type=Path, action="append",
                   help="this recording was made on the floor (repeatable)")
    i.set_defaults(func=_identify)
    q = verbs.add_parser("plot", help="plot a recording")
    q.add_argument("recording", type=Path)
    q.add_argument("--out", default="wcdrive-out/bench")
    q.set_defaults(func=_plot)
