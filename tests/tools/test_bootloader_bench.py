"""The bench path with the real tools: Debian's avrdude flashes a simulated
Mega 2560 through its real, unmodified stk500v2 bootloader behind a pty that resets
the chip when it is opened (DTR); ``wcdrive bench flash`` fails fast and clearly;
the whole flash -> run -> record -> replay -> plot flow on that stand-in."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from wcdrive.boards.simavr.bootloader_mega import BOOT_START, BOOTLOADER_HEX, BootloaderBoard, parse_ihex
from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.protocol.spec import build_id, text
from wcdrive.tools import bench
from wcdrive.tools.cli import main as wcdrive_main
from wcdrive.transports.pty_bridge import PtyBridge
from wcdrive.transports.recording import Recording

pytestmark = [pytest.mark.simavr,
              pytest.mark.skipif(shutil.which("avrdude") is None or not BOOTLOADER_HEX.exists(),
                                 reason="needs Debian's avrdude and arduino-core-avr")]

#: A second program, not final_control: says TINY every 50 ms on USART0 at 115200.
TINY_C = r"""
#include <avr/io.h>
#include <util/delay.h>
int main(void) {
    UCSR0A = 1 << U2X0; UBRR0 = 16;
    UCSR0B = (1 << TXEN0) | (1 << RXEN0);
    for (;;) {
        for (const char *p = "TINY\r\n"; *p; p++) { while (!(UCSR0A & (1 << UDRE0))); UDR0 = *p; }
        _delay_ms(50);
    }
}
"""

SHORT = """name = "bench_short"
description = "Two wheel-speed steps in 3 s: the bench flow's CI scenario."
host_rate_hz = 10

[[segment]]
wheel = [5.0, 5.0]
duration = 1.5

[[segment]]
wheel = [10.0, 10.0]
duration = 1.5
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The tiny program built for the Mega 2560 and for an Uno's ATmega328P."""
    out = tmp_path_factory.mktemp("tiny")
    (out / "tiny.c").write_text(TINY_C)
    hexes = {}
    for mcu in ("atmega2560", "atmega328p"):
        elf = out / f"tiny-{mcu}.elf"
        subprocess.run(["avr-gcc", f"-mmcu={mcu}", "-DF_CPU=16000000UL", "-Os", "-o", str(elf),
                        str(out / "tiny.c")], check=True)
        hexes[mcu] = out / f"tiny-{mcu}.hex"
        subprocess.run(["avr-objcopy", "-O", "ihex", "-R", ".eeprom", str(elf), str(hexes[mcu])], check=True)
    return hexes


@pytest.fixture(scope="module")
def firmware_hex() -> Path:
    return firmware_elf().with_suffix(".hex")


def stand_in(**kwargs: object) -> PtyBridge:
    """``wcdrive pty --avr --bootloader`` from Python: the board behind a pty whose
    opening resets it."""
    board = BootloaderBoard(**kwargs)  # type: ignore[arg-type]
    bridge = PtyBridge(board, on_open=board.dtr).start()
    board.start()
    return bridge


@pytest.fixture
def bridge() -> Iterator[PtyBridge]:
    b = stand_in()
    yield b
    b.close()


def avrdude(port: str, hex_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["avrdude", "-c", "wiring", "-p", "m2560", "-P", port, "-b", "115200", "-D",
                           "-U", f"flash:w:{hex_path}:i"], capture_output=True, text=True, timeout=40)


def read_for(port: str, seconds: float) -> tuple[bytes, float | None]:
    """What the board sends in ``seconds`` after the port is opened, and when (s after
    the open) the first ``TINY`` line came."""
    with serial.Serial(port, 115200, timeout=0.02) as link:
        opened = time.monotonic()
        data, first = b"", None
        while time.monotonic() < opened + seconds:
            data += link.read(512)
            if first is None and b"TINY\r\n" in data:
                first = time.monotonic() - opened
        return data, first


class PtyCommand:
    """``wcdrive pty --avr --bootloader ...`` as a process; ``device`` is its pty."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "wcdrive", "pty", "--avr", "--bootloader", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.device = self.proc.stdout.readline().strip()
        assert self.device.startswith("/dev/pts/"), self.proc.stderr.read() if self.proc.stderr else ""

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(timeout=10)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()


@pytest.mark.thorough       # 16 s; at the fast depth bench flash goes through the same bootloader
def test_avrdude_flashes_two_programs_through_the_real_bootloader_and_the_flash_is_kept(
        tmp_path: Path, tiny: dict[str, Path], firmware_hex: Path) -> None:
    flash_file = tmp_path / "mega.flash"
    pty = PtyCommand("--flash-file", str(flash_file))
    try:
        # A blank chip: the bootloader runs, no program does.
        data, _ = read_for(pty.device, 1.5)
        assert data == b""
        t0 = time.monotonic()
        done = avrdude(pty.device, firmware_hex)
        took = time.monotonic() - t0
        assert done.returncode == 0, done.stderr
        assert "device signature = 0x1e9801" in done.stderr and "bytes of flash verified" in done.stderr
        print(f"avrdude final_control.hex: {took:.1f} s")
        t0 = time.monotonic()
        version = text("FIRMWARE_VERSION")
        assert bench.read_hello(pty.device) == f"HELLO:3,final_control,{version},{build_id()},0"
        print(f"hello after open: {time.monotonic() - t0:.1f} s")
        t0 = time.monotonic()
        done = avrdude(pty.device, tiny["atmega2560"])
        print(f"avrdude tiny.hex: {time.monotonic() - t0:.1f} s")
        assert done.returncode == 0, done.stderr
        # Each open resets the chip into its bootloader, which leaves for the program
        # about 0.8 s later: the first TINY comes that late (50 ms without a reset).
        for _ in range(2):
            data, first = read_for(pty.device, 1.6)
            assert b"TINY\r\n" in data and first is not None and 0.6 < first < 1.4, (data, first)
    finally:
        assert pty.stop() == 130
    # The flash file keeps the program (and the bootloader) for the next run.
    image = flash_file.read_bytes()
    boot = parse_ihex(BOOTLOADER_HEX.read_text())
    assert all(image[a:a + len(d)] == d for a, d in boot.items()) and min(boot) == BOOT_START
    pty = PtyCommand("--flash-file", str(flash_file))
    try:
        assert b"TINY\r\n" in read_for(pty.device, 1.6)[0]
    finally:
        pty.stop()


def _timed_flash(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, float]:
    t0 = time.monotonic()
    status = wcdrive_main(["bench", "flash", *args])
    return status, capsys.readouterr().err, time.monotonic() - t0


@pytest.mark.thorough
def test_bench_flash_fails_fast_and_clearly(tmp_path: Path, tiny: dict[str, Path],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    timings = {}
    status, err, timings["no device"] = _timed_flash(["--port", str(tmp_path / "ttyACM9")], capsys)
    assert status == 2 and "no board at" in err and "does not exist" in err, err
    status, err, timings["url"] = _timed_flash(["--port", "simavr://"], capsys)
    assert status == 2 and "is a URL, not a serial device" in err, err
    status, err, timings["not a tty"] = _timed_flash(["--port", "/dev/null"], capsys)
    assert status == 2 and "not a serial device" in err, err
    b = stand_in()
    try:
        status, err, timings["wrong chip"] = _timed_flash(
            ["--port", b.device, "--hex", str(tiny["atmega328p"])], capsys)
        assert status == 2 and "ATmega328P" in err and "26 jmp entries" in err, err
        with open(b.device, "rb") as held:            # another program holds the port
            holder = subprocess.Popen(["sleep", "30"], stdin=held)
        try:
            status, err, timings["busy"] = _timed_flash(["--port", b.device], capsys)
        finally:
            holder.kill()
            holder.wait()
        assert status == 2 and "is busy" in err and f"{holder.pid} (sleep 30)" in err, err
    finally:
        b.close()
    # A port with nothing behind it: a pty no board answers on.
    master, slave = os.openpty()
    dead = os.ttyname(slave)
    os.close(slave)
    try:
        status, err, timings["no bootloader"] = _timed_flash(["--port", dead], capsys)
    finally:
        os.close(master)
    assert status == 2 and "no bootloader answered" in err, err
    print(" ".join(f"{k}: {v:.2f} s" for k, v in timings.items()))
    assert timings.pop("no bootloader") < 8.0 + 4.0
    assert max(timings.values()) < 3.0, timings


def test_bench_flash_confirms_the_build_id_or_says_the_board_did_not_answer(
        bridge: PtyBridge, tiny: dict[str, Path], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    status, err, took = _timed_flash(["--port", bridge.device], capsys)
    print(f"bench flash (final_control): {took:.1f} s")
    assert status == 0, err
    assert f"build {build_id()} is the HEX's" in err
    # tiny never says hello: 2 s of waiting for it (its lines start 0.8 s after the
    # reset) shows that as well as the bench's 6 s
    read_hello = bench.read_hello
    monkeypatch.setattr(bench, "read_hello", lambda port: read_hello(port, timeout=2.0))
    with pytest.raises(bench.FlashError, match="did not answer hello"):
        bench.flash(bridge.device, tiny["atmega2560"])


def test_the_build_id_check_compares_with_the_hex(firmware_hex: Path) -> None:
    runs = bench.check_hex(firmware_hex)
    assert bench.check_build_id(f"HELLO:3,final_control,3.0.0,{build_id()}", runs, firmware_hex) == build_id()
    # a board with drive profiles ends the line with the profile in force
    with_profile = f"HELLO:3,final_control,4.0.0,{build_id()},2"
    assert bench.check_build_id(with_profile, runs, firmware_hex) == build_id()
    other = "0123abcd" if build_id() != "0123abcd" else "89abcdef"
    with pytest.raises(bench.FlashError, match=f"says build {other}.*not in final_control.hex"):
        bench.check_build_id(f"HELLO:3,final_control,3.0.0,{other}", runs, firmware_hex)


@pytest.mark.thorough
def test_the_whole_bench_flow_on_the_bootloader_stand_in(tmp_path: Path, bridge: PtyBridge,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT)
    rec, plots = tmp_path / "run.wcrec.json", tmp_path / "plots"
    steps = {}
    t0 = time.monotonic()
    assert wcdrive_main(["bench", "flash", "--port", bridge.device]) == 0
    steps["flash"] = time.monotonic() - t0
    t0 = time.monotonic()
    assert wcdrive_main(["bench", "run", str(scenario), "--port", bridge.device, "--record", str(rec),
                         "--yes"]) == 0
    steps["run+record"] = time.monotonic() - t0
    t0 = time.monotonic()
    assert wcdrive_main(["bench", "replay", str(rec)]) == 0
    steps["replay"] = time.monotonic() - t0
    assert "board and port agree" in capsys.readouterr().out
    t0 = time.monotonic()
    assert wcdrive_main(["bench", "plot", str(rec), "--out", str(plots)]) == 0
    steps["plot"] = time.monotonic() - t0
    assert (plots / "bench.png").stat().st_size > 10_000
    recording = Recording.load(rec)
    assert recording.meta["build_id"] == build_id() and b"10.000" in recording.sent_bytes
    print(" ".join(f"{k}: {v:.1f} s" for k, v in steps.items()))


def test_bench_run_asks_about_the_wheels_unless_yes(monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    asked: list[str] = []

    def no(prompt: str) -> str:
        asked.append(prompt)
        return "n"

    monkeypatch.setattr("builtins.input", no)
    assert wcdrive_main(["bench", "run", "step_response", "--port", "/dev/ttyACM9"]) == 2
    assert "wheels off the ground" in asked[0] and "not started" in capsys.readouterr().err

    def eof(prompt: str) -> str:
        raise EOFError

    monkeypatch.setattr("builtins.input", eof)
    assert wcdrive_main(["bench", "run", "step_response", "--port", "/dev/ttyACM9"]) == 2
    # --yes goes straight on (here to a port that is not there).
    monkeypatch.setattr("builtins.input", no)
    asked.clear()
    assert wcdrive_main(["bench", "run", "step_response", "--port", "/dev/ttyACM9", "--yes"]) == 3
    assert not asked and "/dev/ttyACM9" in capsys.readouterr().err


def test_ctrl_c_stops_the_chair_then_keeps_a_partial_recording_that_replays(
        tmp_path: Path, firmware_hex: Path) -> None:
    b = stand_in(program=firmware_hex)
    scenario = tmp_path / "long.toml"
    scenario.write_text(SHORT.replace("duration = 1.5", "duration = 30.0"))
    rec = tmp_path / "partial.wcrec.json"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    try:
        proc = subprocess.Popen([sys.executable, "-m", "wcdrive", "bench", "run", str(scenario), "--port",
                                 b.device, "--record", str(rec), "--yes"], stderr=subprocess.PIPE,
                                text=True, env=env)
        assert proc.stderr is not None
        err = ""
        deadline = time.monotonic() + 20
        while "driving" not in err and time.monotonic() < deadline:
            err += proc.stderr.readline()
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
        err += proc.communicate(timeout=15)[1]
    finally:
        b.close()
    assert proc.returncode == 130, err
    assert "the chair was stopped" in err and "partial recording" in err, err
    recording = Recording.load(rec)
    assert recording.meta["partial"] is True
    sent = recording.sent_bytes.rstrip(b"\n")
    assert b"5.000" in sent and sent.endswith(b"x:0.000,t:0.000,*" + sent[-4:])   # the stop went last
    assert wcdrive_main(["bench", "replay", str(rec)]) == 0
