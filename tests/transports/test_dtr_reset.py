"""The DTR model: opening a simulated board's pty resets it, as opening a
real Mega's port does, and the host copes with that and with a reset mid-run: it
greets the board again, drives on, and its odometry carries on from where it was
instead of jumping back to the origin when the board's counts restart at 0."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest
import serial

import wcdrive
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.boards.simavr.mega_board import MegaBoard
from wcdrive.errors import WcdriveNeutralError
from wcdrive.transports.pty_bridge import PtyBridge


def test_opening_the_pty_resets_the_board_every_time() -> None:
    board = SimulatedBoard()
    bridge = PtyBridge(board.start(), on_open=board.dtr).start()
    try:
        boots = []
        for _ in range(3):
            with serial.Serial(bridge.device, 115200, timeout=0.05) as link:
                data = b""
                end = time.monotonic() + 0.6
                while time.monotonic() < end:
                    data += link.read(256)
            boots.append(data.count(b",EXTERNAL\r\n"))
        assert boots == [1, 1, 1] and bridge.opens == 3
    finally:
        bridge.close()


@pytest.mark.parametrize("args", [["pty"], pytest.param(["pty", "--avr"], marks=pytest.mark.simavr)],
                         ids=["pty", "pty-avr"])
def test_wcdrive_pty_resets_its_board_at_each_open(args: list[str]) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "wcdrive", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        device = proc.stdout.readline().strip()
        boots = []
        for _ in range(2):
            with serial.Serial(device, 115200, timeout=0.05) as link:
                data = b""
                end = time.monotonic() + 1.0
                while time.monotonic() < end:
                    data += link.read(256)
            # The BOOT line comes first (pyserial flushes the input as it opens the port,
            # which may take its head: this board boots at once, with no bootloader). At
            # most the head of one line may come before it: what the old board sent
            # between pyserial's flush and the reset, which the bridge learns of a moment
            # after the open (seen on a loaded machine), cut by the reset as a line is
            # on a real board; LineDecoder reads it as an Unknown before the Boot.
            first = data.split(b"\r\n")[0]
            boot = b"BOOT:final_control,EXTERNAL"
            boots.append(data.count(b",EXTERNAL\r\n") if boot.endswith(first) or first.endswith(boot)
                         else repr(data[:80]))
        assert boots == [1, 1], boots                 # each open: a fresh boot, first thing
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)


def _drive(chair: wcdrive.Wheelchair, seconds: float) -> None:
    """Drives at 0.4 m/s for ``seconds``; after a reset the program drives on once the
    board has confirmed a neutral command (docs/safety.md, "Neutral before motion"):
    that wait does not count in ``seconds``."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            chair.set_velocity(0.4, 0.0)
        except WcdriveNeutralError:
            waited = time.monotonic()
            chair.wait_for_neutral()          # the board reset: a neutral, then on
            end += time.monotonic() - waited
        except wcdrive.WcdriveError:
            pass                              # between the reset and the new hello
        time.sleep(0.05)


@pytest.mark.simavr
@pytest.mark.parametrize("bootloader", [False, pytest.param(True, marks=pytest.mark.thorough)],
                         ids=["mega", "mega-with-bootloader"])
def test_a_reset_mid_run_is_greeted_again_and_odometry_carries_on(elf, bootloader: bool) -> None:
    """With the stk500v2 bootloader the board is silent after each reset, and the link
    is lost: the host's frames that reach the bootloader before the host sees that
    (within ``link_timeout``) make it wait for about 5.5 s of quiet (its
    ``recchar_timeout``) instead of 0.8 s before it starts the firmware. The host
    sends nothing while the link is down, so the board does come back."""
    board: MegaBoard
    if bootloader:
        from wcdrive.boards.simavr.bootloader_mega import BootloaderBoard

        board = BootloaderBoard(program=elf.with_suffix(".hex"))
    else:
        board = MegaBoard(elf, realtime=True)
    bridge = PtyBridge(board, on_open=board.dtr).start()
    board.start()
    try:
        with wcdrive.connect(bridge.device) as chair:
            # The open reset it (the stk500v2 bootloader clears MCUSR before the firmware reads it).
            assert chair.reset_cause == ("NONE" if bootloader else "EXTERNAL")
            _drive(chair, 2.0)
            before = chair.odometry.pose.x
            assert before > 0.1
            sent: list[float] = []
            write = board.write
            board.write = lambda data: (sent.append(time.monotonic()), write(data))[1]  # type: ignore[method-assign]
            reset_at, reset_sim = time.monotonic(), board.mega.time
            board.reset()                                     # DTR pulse, the chair rolling
            if bootloader:
                _drive(chair, 0.5)
                assert "LINK_LOST" in chair.events
                quiet_from = time.monotonic()
                end = quiet_from + 60
                while not ("BOARD_RESET" in chair.events and chair.protocol_version == 4) \
                        and time.monotonic() < end:
                    time.sleep(0.05)                          # nothing to send: the link is down
                back_sim = board.mega.time - reset_sim
                print(f"back {back_sim:.2f} s (simulated) after the reset, "
                      f"{time.monotonic() - reset_at:.1f} s wall")
                assert 3.5 < back_sim < 8.0
                assert [t for t in sent if reset_at + 0.3 < t < quiet_from] == []   # quiet while down
            _drive(chair, 1.5)
            assert "BOARD_RESET" in chair.events and chair.protocol_version == 4
            after = chair.odometry.pose.x
            truth = board.pose()[0]
            # Counts from 0 again on the board; the pose went on forward (without the
            # re-base it would have jumped back by about `before`).
            assert after > before + 0.1, (before, after)
            assert abs(after - truth) < 0.25 * truth, (after, truth)
    finally:
        bridge.close()


def test_a_device_that_comes_back_is_reopened_reset_and_greeted_again(tmp_path) -> None:
    """Unplugged and plugged in again (the pty and its link go, a new board comes
    back under the same link): the session reopens it, which resets the board (DTR);
    it greets the new board, drives it, and the odometry carries on."""
    link = tmp_path / "ttyWC"
    first = SimulatedBoard()
    bridge = PtyBridge(first.start(), link=link, on_open=first.dtr).start()
    second: PtyBridge | None = None
    try:
        with wcdrive.connect(str(link), reconnect_timeout=20) as chair:
            _drive(chair, 1.5)
            before = chair.odometry.pose.x
            assert before > 0.1
            bridge.close()                                    # unplugged
            time.sleep(0.5)
            board = SimulatedBoard()
            second = PtyBridge(board.start(), link=link, on_open=board.dtr).start()
            end = time.monotonic() + 20
            while not ("RECONNECTED" in chair.events and chair.protocol_version == 4) \
                    and time.monotonic() < end:
                time.sleep(0.05)
            assert "RECONNECTED" in chair.events and chair.protocol_version == 4, chair.events
            assert second.opens == 1 and chair.reset_cause == "EXTERNAL"
            _drive(chair, 1.5)
            after = chair.odometry.pose.x
            assert after > before + 0.1, (before, after)
    finally:
        bridge.close()
        if second is not None:
            second.close()


@pytest.mark.simavr
def test_a_bench_run_with_a_reset_in_it_replays_boot_by_boot(elf, tmp_path) -> None:
    from wcdrive.tools import bench
    from wcdrive.tools.replay import replay

    scenario = tmp_path / "short.toml"
    scenario.write_text('name = "short"\ndescription = "3 s"\nhost_rate_hz = 10\n\n'
                        '[[segment]]\nwheel = [5.0, 5.0]\nduration = 1.5\n\n'
                        '[[segment]]\nwheel = [10.0, 10.0]\nduration = 1.5\n')
    board = MegaBoard(elf, realtime=True)
    bridge = PtyBridge(board, on_open=board.dtr).start()
    board.start()
    timer = threading.Timer(2.5, board.reset)             # mid-run, in the second segment
    timer.start()
    try:
        recording = bench.run_scenario(str(scenario), bridge.device)
    finally:
        timer.cancel()
        bridge.close()
    assert recording.received_bytes.count(b"BOOT:final_control") == 2
    report = replay(recording)
    assert report.agrees, report
    assert "the board reset 1 time(s) during the recording" in report.notes and report.ticks > 50
    # A byte the board sent after the reset, changed: the search for where the host's
    # bytes start again does not make it agree.
    stream = recording.received_bytes
    at = stream.index(b"TLM:", stream.rindex(b"BOOT:final_control"))
    for _ in range(4):
        at = stream.index(b"TLM:", at + 1)                # the 5th TLM line after the reset
    chunks, pos = recording.received, 0
    for i, (t, data) in enumerate(chunks):
        if pos <= at + 4 < pos + len(data):
            k = at + 4 - pos
            chunks[i] = (t, data[:k] + (b"9" if data[k:k + 1] != b"9" else b"8") + data[k + 1:])
            break
        pos += len(data)
    tampered = replay(recording)
    assert not tampered.agrees and "boot 1" in str(tampered.mismatch), tampered
