"""The bench tool and replay: sessions recorded from the firmware in simavr (CI's
stand-in for a board on USB) and from the simulated chair replay through the Python
port byte for byte; tampered recordings do not."""

from __future__ import annotations

import time

import pytest
import serial

from wcdrive.protocol.codec import frame
from wcdrive.sim.scenario import ScenarioError
from wcdrive.tools import bench
from wcdrive.tools.cli import main as wcdrive_main
from wcdrive.tools.replay import ReplayError, replay
from wcdrive.transports.recording import Recording, RecordingPort


@pytest.fixture(scope="module")
def simavr_recording(elf) -> Recording:
    """The step-response scenario driven on the ELF in simavr (chair behind the pins)."""
    return bench.run_scenario("step_response", f"simavr://{elf}?realtime=0", speed=4.0)


def test_a_session_on_the_firmware_replays_through_the_port(simavr_recording) -> None:
    report = replay(simavr_recording)
    assert report.agrees, report.mismatch
    assert report.ticks > 10 and report.bytes_fed == len(simavr_recording.sent_bytes) - _unread_tail(
        simavr_recording)
    received = simavr_recording.received_bytes
    assert b"HELLO:4,final_control," in received and b"TLM:" in received
    assert max(int(line.split(b",")[3]) for line in _lines(received)
               if line.startswith(b"TLM:")) > 50           # the motors were driven


def _unread_tail(recording: Recording) -> int:
    """Bytes sent after the last complete tick the replay compared (the final stop)."""
    sent = recording.sent_bytes
    last_rx = max(int(line[4:].split(b",")[1]) for line in _lines(recording.received_bytes)
                  if line.startswith(b"TLM:"))
    return len(sent) - last_rx


def _lines(received: bytes) -> list[bytes]:
    """The complete lines (a recording may end inside the board's last line)."""
    return received.split(b"\r\n")[:-1]


@pytest.mark.parametrize("damage", ["pwm in a TLM line", "a byte the host sent", "a feedback count"])
def test_a_tampered_recording_does_not_replay(simavr_recording, damage: str) -> None:
    rec = Recording(list(simavr_recording.sent), list(simavr_recording.received), {})
    if damage == "a byte the host sent":
        i = next(k for k, (_, d) in enumerate(rec.sent) if b"x:" in d and k > 5)
        t, d = rec.sent[i]
        rec.sent[i] = (t, d.replace(b"x:", b"x:1", 1) if b"x:0" in d else d.replace(b"0", b"1", 1))
    else:
        data = bytearray(rec.received_bytes)
        if damage == "pwm in a TLM line":
            at = data.index(b"TLM:", len(data) // 2)
            fields = bytes(data[at:data.index(b"\r\n", at)]).split(b",")
            fields[3] = b"%d" % (int(fields[3]) ^ 1)
            data[at:data.index(b"\r\n", at)] = b",".join(fields)
        else:
            at = data.index(b"ENC:", len(data) // 2) + 4
            data[at:at + 1] = b"7" if data[at:at + 1] != b"7" else b"8"
        rec.received = [(0.0, bytes(data))]
    report = replay(rec)
    assert not report.agrees


def test_ticks_before_hello_are_placed_by_the_timer0_model() -> None:
    port = RecordingPort(serial.serial_for_url("wcsim://?speed=5", timeout=0.1))
    try:
        time.sleep(0.12)                                   # ~12 ticks before hello
        port.write(b"hello\n")
        for i in range(30):
            port.write(frame(b"x:0.400,t:0.100,", i) if i % 3 else b"rp1.500,lp1.400,")
            time.sleep(0.02)
            port.read(4096)
        time.sleep(0.05)
        port.read(100000)
    finally:
        port.close()
    report = replay(port.recording)
    assert report.agrees, report.mismatch
    assert any("before hello" in n for n in report.notes)


def test_a_recording_without_the_boot_line_is_refused() -> None:
    rec = Recording([(0.0, b"hello\n")], [(0.0, b"ENC:0,0,VEL:0.00,0.00,MODE:CMDVEL\r\n" * 3)])
    with pytest.raises(ReplayError, match="BOOT"):
        replay(rec)


SILENCE = """
name = "silence"
description = "1 s at 0.5 m/s, then the host goes silent for 2 s"
host_rate_hz = 20
settle_s = 0.3

[[segment]]
cmdvel = [0.5, 0.0]
duration = 1.0

[[segment]]
silence = true
duration = 2.0
"""


def test_bench_cli_records_replays_and_plots(tmp_path, elf, capsys) -> None:
    scenario = tmp_path / "silence.toml"
    scenario.write_text(SILENCE)
    out = tmp_path / "wd.wcrec.json"
    # 2 s of wall-clock silence is > 0.55 s of board time even on a loaded machine.
    assert wcdrive_main(["bench", "run", str(scenario), "--port", f"simavr://{elf}?realtime=0", "--record",
                         str(out), "--plot", str(tmp_path / "plots")]) == 0
    assert (tmp_path / "plots" / "bench.png").stat().st_size > 10000
    assert wcdrive_main(["bench", "replay", str(out)]) == 0
    assert "board and port agree" in capsys.readouterr().out
    assert b"EVT:WATCHDOG" in Recording.load(out).received_bytes
    assert wcdrive_main(["bench", "flash", "--port", "/dev/ttyACM7", "--dry-run"]) == 0
    flash = capsys.readouterr().out
    assert "avrdude -p atmega2560 -c wiring -P /dev/ttyACM7" in flash and "final_control.hex:i" in flash
    assert wcdrive_main(["bench", "flash", "--port", "simavr://", "--dry-run"]) == 2


def test_bench_run_refuses_a_robot_that_is_not_the_chair() -> None:
    """A scenario's lines are the chair's protocol: on the Eddie ``bench run`` says so
    before sending any (it sent them, and the Eddie answered ``ERROR``)."""
    with pytest.raises(ScenarioError, match=r"replays the wheelchair's commands; eddie.*is a EddieRobot"):
        bench.run_scenario("step_response", "eddie+sim://?speed=8", speed=8.0)
