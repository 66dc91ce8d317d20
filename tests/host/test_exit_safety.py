"""Every way a program ends leaves the chair stopped, before the board's watchdog would
have stopped it (500 ms after the last command), and the command-line tools end on
Ctrl-C with status 130 and no traceback.

A script in its own interpreter drives a simulated board that this test owns, through a
pseudo-terminal (``wcdrive.connect(<pty path>)``, the real serial code path). The test
watches the board from inside (every line its firmware finishes, on the board's clock)
and ends the script: SIGINT, SIGTERM, leaving the interpreter without ``close()``, or
dropping the last reference to the chair while the interpreter lives on.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.protocol.codec import encode_cmdvel
from wcdrive.transports.pty_bridge import PtyBridge

STOP = encode_cmdvel(0.0, 0.0)
DRIVE = encode_cmdvel(0.5, 0.0)

SCRIPT = textwrap.dedent("""
    import gc, signal, sys, time
    import wcdrive

    path, how = sys.argv[1], sys.argv[2]
    if how == "own":        # the program's own SIGTERM handler: it owns the exit
        def own(signum, frame):
            print("own handler", flush=True)
            raise SystemExit(7)
        signal.signal(signal.SIGTERM, own)
    chair = wcdrive.connect(path)
    print("driving", flush=True)
    end = time.monotonic() + (0.6 if how in ("exit", "gc", "stop_all") else 60)
    while time.monotonic() < end:
        chair.set_velocity(0.5, 0.0)
        time.sleep(0.05)
    if how == "gc":
        del chair
        gc.collect()
        print("collected", flush=True)
        time.sleep(60)
    if how == "stop_all":
        wcdrive.stop_all()
        print("collected", flush=True)
        time.sleep(60)
    # "exit": the end of the script, with the chair never closed
""")


class Watched:
    """A simulated board (at the wall clock's pace) behind a pty, with every line its
    firmware finishes logged as (board millis, command) and every watchdog stop."""

    def __init__(self) -> None:
        self.board = SimulatedBoard(speed=1.0)
        self.lines: list[tuple[int, bytes]] = []
        self.watchdog: list[int] = []
        self._partial = b""
        fw, timer = self.board.loop.fw, self.board.loop.timer
        feed, tick = fw.feed, fw.tick

        def probed_feed(data: bytes) -> bytes:
            out = feed(data)
            self._partial += data
            *done, self._partial = self._partial.split(b"\n")
            for line in done:
                body = line.rpartition(b"*")[0].partition(b":")[2] if line.startswith(b"$") else line
                self.lines.append((timer.millis, body))
            return out

        def probed_tick(now: int, *args: int, **kwargs: int) -> bytes:
            out = tick(now, *args, **kwargs)
            if b"EVT:WATCHDOG" in out:
                self.watchdog.append(now)
            return out

        fw.feed = probed_feed        # type: ignore[method-assign]
        fw.tick = probed_tick        # type: ignore[method-assign,assignment]
        self.bridge = PtyBridge(self.board.start()).start()

    def stop_after_driving(self) -> tuple[int, int] | None:
        """(millis of the last drive command, millis of the stop after it), or None."""
        with self.board._lock:
            lines = list(self.lines)
        last_drive = max((i for i, (_, body) in enumerate(lines) if body == DRIVE), default=None)
        if last_drive is None:
            return None
        stop = next((m for m, body in lines[last_drive + 1:] if body == STOP), None)
        return None if stop is None else (lines[last_drive][0], stop)

    def close(self) -> None:
        self.bridge.close()


@pytest.fixture
def watched():
    w = Watched()
    yield w
    w.close()


def _start(path: str, how: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT, path, how], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd="/")
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line == "driving\n", (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGHUP", "own", "exit", "gc", "stop_all"])
def test_ending_a_driving_script_stops_the_chair_before_the_watchdog(watched, how: str) -> None:
    """However a script lets go of a driving chair (a signal, its own SIGTERM handler
    left in place, the end of the script, garbage collection, ``wcdrive.stop_all()``),
    the chair gets a stop within 300 ms of the last drive command, before the watchdog."""
    proc = _start(watched.bridge.path, how)
    try:
        if how.startswith("SIG") or how == "own":
            time.sleep(0.4)
            proc.send_signal(signal.SIGTERM if how == "own" else getattr(signal, how))
        elif how in ("gc", "stop_all"):
            assert proc.stdout is not None
            assert proc.stdout.readline() == "collected\n"
        deadline = time.monotonic() + 10
        while (found := watched.stop_after_driving()) is None:
            assert time.monotonic() < deadline, (
                f"no stop after the last drive command; watchdog at {watched.watchdog}; "
                f"the script said {proc.stderr.read() if proc.poll() is not None else '(running)'}")
            time.sleep(0.01)
        last_drive, stop = found
        assert stop - last_drive < 300, f"the stop came {stop - last_drive} ms after the last command"
        assert not [m for m in watched.watchdog if m > last_drive], "the watchdog stopped it first"
        state = watched.board.loop.fw.state
        assert state.targetR == 0.0 and state.targetL == 0.0
        if how in ("gc", "stop_all"):
            assert proc.poll() is None                      # the finalizer or stop_all, not the exit
    finally:
        if how in ("gc", "stop_all") or sys.exc_info()[0] is not None:
            proc.kill()
        out, err = proc.communicate(timeout=10)              # the others end by themselves
    expected = {"SIGINT": -signal.SIGINT, "SIGTERM": -signal.SIGTERM, "SIGHUP": -signal.SIGHUP, "own": 7,
                "exit": 0, "gc": -signal.SIGKILL, "stop_all": -signal.SIGKILL}
    assert proc.returncode == expected[how], err
    if how == "SIGINT":
        assert "KeyboardInterrupt" in err                   # the script's own traceback
    if how == "own":
        assert "own handler" in out                         # left in place, it ran


# ---- the command-line tools on Ctrl-C -------------------------------------------------------
SCENARIO = """
name = "long"
description = "20 s at 0.3 m/s"
host_rate_hz = 20
settle_s = 0.3

[[segment]]
cmdvel = [0.3, 0.0]
duration = 20.0
"""


#: ``wcdrive ARGS`` as the console script runs it, saying when its imports are done.
MAIN = ("import sys; from wcdrive.tools.cli import main; print('imported', file=sys.stderr, flush=True); "
        "sys.exit(main(sys.argv[1:]))")


def _interrupt(args: list[str], ready: str, stream: str = "stdout", delay: float = 0.3
               ) -> tuple[int, str, str]:
    """Runs ``wcdrive ARGS``, waits for ``ready`` on its ``stream``, sends SIGINT; returns
    (status, stdout, stderr)."""
    proc = subprocess.Popen([sys.executable, "-c", MAIN, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd="/")
    seen: list[str] = []
    found = threading.Event()
    source = proc.stdout if stream == "stdout" else proc.stderr
    assert source is not None

    def watch() -> None:
        for line in source:
            seen.append(line)
            if ready in line:
                found.set()

    reader = threading.Thread(target=watch, daemon=True)
    reader.start()
    try:
        assert found.wait(60), (args, "".join(seen))
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        status = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(timeout=5)
    other = proc.stderr if stream == "stdout" else proc.stdout
    rest = other.read() if other is not None else ""
    out, err = ("".join(seen), rest) if stream == "stdout" else (rest, "".join(seen))
    return status, out, err


def test_wcdrive_pty_ends_cleanly_on_ctrl_c() -> None:
    status, _, err = _interrupt(["pty"], "/dev/pts/")
    assert status == 130 and "Traceback" not in err, err


def test_wcdrive_sim_ends_cleanly_on_ctrl_c(tmp_path: Path) -> None:
    endless = tmp_path / "endless.toml"
    endless.write_text('name = "endless"\ndescription = "a day"\nhost_rate_hz = 10\n\n'
                       '[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 86400.0\n')
    status, _, err = _interrupt(["sim", str(endless), "--no-plots"], "imported", stream="stderr",
                                delay=0.5)
    assert status == 130 and "Traceback" not in err and "interrupted" in err, err


def test_wcdrive_can_gateway_ends_cleanly_on_ctrl_c() -> None:
    status, _, err = _interrupt(["can-gateway", "--chair", "wcsim://", "--interface", "virtual",
                                 "--channel", "wc-exit"], "Ctrl-C to stop")
    assert status == 130 and "Traceback" not in err, err


def test_wcdrive_bench_run_stops_the_chair_and_keeps_the_recording_on_ctrl_c(tmp_path: Path) -> None:
    scenario = tmp_path / "long.toml"
    scenario.write_text(SCENARIO)
    out = tmp_path / "run.wcrec.json"
    status, _, err = _interrupt(["bench", "run", str(scenario), "--port", "sim://", "--record", str(out)],
                                "driving", stream="stderr", delay=0.5)
    assert status == 130 and "Traceback" not in err, err
    assert "the chair was stopped" in err and "partial recording" in err, err
    from wcdrive.transports.recording import Recording

    recording = Recording.load(out)
    assert recording.meta["interrupted"] is True
    sent = recording.sent_bytes
    assert b"x:0.300,t:0.000," in sent and sent.rstrip(b"\n").endswith(b"x:0.000,t:0.000,*" + sent[-5:-1])
    assert os.path.getsize(out) > 1000
