"""The serial drop-in for ros2_control hardware interfaces: a plugin written for the
seed-era board, played byte for byte against ``wcdrive pty --avr`` (the firmware in
simavr, the chair on its pins, behind a pty), reads back the speeds the chair's wheels
turn at once the board has been told ``feedback_form`` 1 and saved it.

The plugin's serial side, as it is written: it opens the port (which resets the board:
DTR), writes ``rp0.0,lp0.0,\\n``, waits 2 s, then writes ``r[pn]%05.2f,l[pn]%05.2f,``
(wheel rad/s, no line end) every 10 ms: zeros for ``IDLE_S`` (what diff_drive_controller
hands it before the first ``cmd_vel`` arrives), then the phases' speeds; and it reads
lines, taking the wheel speeds from ``r([pn])-?(\\d*\\.?\\d+)`` and
``l([pn])-?(\\d*\\.?\\d+)``. The 2 s wait is kept: it is the plugin's own. The board
runs in real time (``--realtime``), as the chair's does, so the plugin's wall-clock
pacing is the board's.

The port-level rules of the form are in tests/firmware/test_feedback_form.py."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import serial

pytestmark = pytest.mark.simavr

PLUGIN_R = re.compile(r"r([pn])-?(\d*\.?\d+)")
PLUGIN_L = re.compile(r"l([pn])-?(\d*\.?\d+)")
VEL = re.compile(r"ENC:-?\d+,-?\d+,VEL:(-?[\d.]+),(-?[\d.]+),MODE:WHEEL")
#: The plugin's write period and its wait after the first command.
PERIOD_S = 0.01
ACTIVATE_WAIT_S = 2.0
#: The zeros written before the first phase. The opening ``rp0.0,lp0.0,`` may reach the
#: board before its receiver is on (the DTR reset's boot, slower in wall time on a
#: loaded machine; a real Mega's bootloader takes it anyway): without these the board
#: would never see a neutral command and would refuse every phase.
IDLE_S = 0.3
#: (right, left) rad/s and how long each is written: forward with a turn, then back.
#: The chair follows slowly (its mass, the casters swinging round on the reversal), so
#: a phase's end is not its command: the truth is the wheels' speeds, not the command.
PHASES = ((2.0, 1.0, 4.0), (-1.0, -1.5, 4.0))
#: Over a phase's last second, how far the mean of what the plugin reads may be from the
#: mean of the wheels' true speeds (rad/s): a 50 ms tick's count is 0.013 rad/s, the
#: print 0.005, and the line reaches the plugin up to a tick after the speeds it measured
#: (the chair still accelerates at up to 0.5 rad/s^2 there).
MEAN_TOLERANCE = 0.05
#: ... and the least speed (rad/s) each wheel turns the commanded way by then.
MOVING = 0.1


@dataclass
class Reading:
    """One line the plugin read: when, the line, what its expressions took from it
    ((right, left) or None) and, where the board runs in this process, the wheels'
    true speeds (right, left) when it came."""

    t: float
    line: str
    plugin: tuple[float, float] | None
    truth: tuple[float, float] | None = None


@dataclass
class Plugin:
    """The hardware interface's serial side (``on_activate``, ``write``, ``read``)."""

    device: str
    truth: Callable[[], tuple[float, float]] | None = None
    readings: list[Reading] = field(default_factory=list)

    def run(self, phases: tuple[tuple[float, float, float], ...]) -> list[tuple[float, float, float, float]]:
        """Opens the port, activates, writes each phase's command at 100 Hz; returns
        each phase's (start, end, ...) wall times with its command."""
        spans = []
        with serial.Serial(self.device, 115200, timeout=0.005) as link:
            stop = threading.Event()
            reader = threading.Thread(target=self._read, args=(link, stop), daemon=True)
            reader.start()
            try:
                link.write(b"rp0.0,lp0.0,\n")
                time.sleep(ACTIVATE_WAIT_S)
                for k, (right, left, seconds) in enumerate(((0.0, 0.0, IDLE_S), *phases)):
                    start = time.monotonic()
                    n = 0
                    while time.monotonic() < start + seconds:
                        link.write(b"r%s%05.2f,l%s%05.2f," % (
                            b"n" if right < 0 else b"p", abs(right), b"n" if left < 0 else b"p", abs(left)))
                        n += 1
                        time.sleep(max(0.0, start + n * PERIOD_S - time.monotonic()))
                    if k:                                   # the idle zeros are no phase
                        spans.append((start, time.monotonic(), right, left))
            finally:
                stop.set()
                reader.join(timeout=2)
        return spans

    def _read(self, link: serial.Serial, stop: threading.Event) -> None:
        buf = b""
        while not stop.is_set():
            buf += link.read(256)
            *lines, buf = buf.split(b"\n")
            for raw in lines:
                text = raw.rstrip(b"\r").decode("ascii", "replace")
                r, l_ = PLUGIN_R.search(text), PLUGIN_L.search(text)
                plugin = None
                if r and l_:
                    plugin = ((-1.0 if r[1] == "n" else 1.0) * float(r[2]),
                              (-1.0 if l_[1] == "n" else 1.0) * float(l_[2]))
                truth = self.truth() if self.truth is not None else None
                self.readings.append(Reading(time.monotonic(), text, plugin, truth))


def tell_the_form(device: str, form: int) -> list[str]:
    """As any host does once: ``set:feedback_form=<form>`` and ``save`` (unframed,
    before hello); waits until the save is written (176 bytes, 3.4 ms each). Returns the
    lines the board sent."""
    with serial.Serial(device, 115200, timeout=0.05) as link:
        time.sleep(0.3)                                 # the board boots (DTR)
        link.write(b"set:feedback_form=%d\nsave\n" % form)
        data = b""
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            data += link.read(256)
    return data.decode("ascii", "replace").split("\r\n")


def tell_the_form_by_host(device: str, form: int) -> float:
    """The same through wcdrive's host (``hello:4``, framed): ``set_param`` and
    ``save_params``, then a wait for the board to write the block before the port
    closes (the next open resets the board). Returns the value the board holds."""
    import wcdrive
    from wcdrive.host.wheelchair import Wheelchair

    with wcdrive.connect(device) as chair:
        assert isinstance(chair, Wheelchair)
        value = chair.set_param("feedback_form", form)
        chair.save_params()
        time.sleep(0.9)                                 # 176 bytes, 3.4 ms each
    return value


@contextmanager
def wcdrive_pty(elf: Path) -> Iterator[str]:
    command = [sys.executable, "-m", "wcdrive", "pty", "--avr", "--realtime", "--elf", str(elf)]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        yield proc.stdout.readline().strip()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)


def check_phases(plugin: Plugin, spans: list[tuple[float, float, float, float]]) -> None:
    """In each phase's last second: every feedback line gives the plugin exactly the
    speeds its ``VEL`` fields give (right first); each wheel turns the commanded way,
    ``MOVING`` or faster; with the truth at hand, the mean of what the
    plugin read is the mean of the wheels' true speeds within ``MEAN_TOLERANCE``."""
    for _start, end, right, left in spans:
        window = [r for r in plugin.readings if end - 1.0 <= r.t <= end and r.line.startswith("ENC:")]
        # 20 Hz; on a loaded machine the simulation falls behind the wall clock
        assert len(window) >= 5, (right, left, len(window))
        for r in window:
            vel = VEL.match(r.line)
            assert vel is not None and r.plugin is not None, r.line
            assert r.plugin == (float(vel[2]), float(vel[1])), r.line
            assert r.plugin[0] * right > 0 and abs(r.plugin[0]) >= MOVING, r.line
            assert r.plugin[1] * left > 0 and abs(r.plugin[1]) >= MOVING, r.line
        read = [r.plugin for r in window if r.plugin is not None]
        mean_r = sum(p[0] for p in read) / len(read)
        mean_l = sum(p[1] for p in read) / len(read)
        truths = [r.truth for r in window if r.truth is not None]
        if truths:
            true_r = sum(t[0] for t in truths) / len(truths)
            true_l = sum(t[1] for t in truths) / len(truths)
            assert abs(mean_r - true_r) <= MEAN_TOLERANCE and abs(mean_l - true_l) <= MEAN_TOLERANCE, (
                (mean_r, true_r), (mean_l, true_l))


def test_a_seed_era_ros2_control_plugin_reads_the_wheels_behind_wcdrive_pty(elf: Path) -> None:
    with wcdrive_pty(elf) as device:
        told = tell_the_form(device, 1)
        assert "PAR:feedback_form,1" in told, told
        plugin = Plugin(device)
        spans = plugin.run(PHASES)     # 4 s forward: the neutral opening on a loaded machine
    # its open reset the board, which loaded the form it had saved
    assert any(r.line == "EVT:PARAMS_LOADED" for r in plugin.readings[:5]), plugin.readings[:5]
    check_phases(plugin, spans)
    # from the first tick on, no feedback line left it reading nothing
    feedback = [r for r in plugin.readings if r.line.startswith("ENC:")]
    assert feedback and all(r.plugin is not None for r in feedback[1:])


def test_the_plugin_reads_the_plants_wheel_speeds(elf: Path) -> None:
    """The same play against what ``wcdrive pty --avr`` builds (``MegaBoard`` behind a
    ``PtyBridge`` that resets it at each open), in this process, so that the wheels'
    true speeds are at hand: what the plugin reads is what the plant's wheels turn at.
    Here wcdrive's own host tells the board the form."""
    from wcdrive.boards.simavr.mega_board import MegaBoard
    from wcdrive.transports.pty_bridge import PtyBridge

    board = MegaBoard(elf, realtime=True)
    bridge = PtyBridge(board, on_open=board.dtr).start()
    board.start()
    try:
        assert tell_the_form_by_host(bridge.device, 1) == 1
        plant = board.plant
        assert plant is not None

        def truth() -> tuple[float, float]:
            return board.between_steps(lambda _: (plant.right.speed, plant.left.speed))

        plugin = Plugin(bridge.device, truth)
        spans = plugin.run(PHASES[:1])
        check_phases(plugin, spans)
    finally:
        bridge.close()
        board.close()


def test_without_the_form_the_plugin_reads_nothing(elf: Path) -> None:
    """The default (a blank EEPROM): the seed's lines, which the plugin's expressions
    do not match, so it reads zeros: what the form is for."""
    with wcdrive_pty(elf) as device:
        plugin = Plugin(device)
        plugin.run(((1.0, 1.0, 1.0),))
    feedback = [r for r in plugin.readings if r.line.startswith("ENC:")]
    assert len(feedback) >= 40 and all(r.plugin is None for r in feedback)
    assert any(r.line == "EVT:PARAMS_DEFAULT,blank" for r in plugin.readings[:5])
