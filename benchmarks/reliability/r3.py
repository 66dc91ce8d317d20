"""R3, faults mid-motion: the link cut, the device unplugged and a DTR reset, on the
firmware in simavr at real time behind a ``FaultyPort`` (``firmware_r3``)."""

from __future__ import annotations

import math
import random
import re
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import serial

from wcdrive.protocol.spec import integer, real
from wcdrive.transports.faulty import FaultyPort
from wcdrive.transports.port import Port

if TYPE_CHECKING:
    from wcdrive.boards.simavr.mega_board import MegaBoard
    from wcdrive.boards.simavr.virtual_mega import VirtualMega

from .common import ElfPath

# ---- R3: link cut, unplug and DTR reset mid-motion (the firmware in simavr, live) -----
R3_KINDS = ("link cut", "unplug", "DTR reset")
WHEEL_RADIUS = real("WHEEL_RADIUS")
WATCHDOG_S = integer("WATCHDOG_MS") / 1000
EMERGENCY_DECEL = real("EMERGENCY_DECEL")
PERIOD_S = integer("CONTROL_PERIOD_MS") / 1000
HOST_PERIOD_S = 0.05            # the host's motion commands: 20 Hz
STANDSTILL_MPS = 0.01
RECOVERY_TIMEOUT_S = 5.0
NEUTRAL_TIMEOUT_S = 2.0         # for the board to confirm a neutral command (host seconds at pace 1)
_ACK = re.compile(rb"ACK:(\d+)(?:#[0-9A-F]{2}\*[0-9A-F]{4})?\r\n")   # plain (v3) or framed (v4)
_BOOT = re.compile(rb"BOOT:[^,\r\n]*,([A-Z_]+)\r\n")

Sample = tuple[int, int, int, float, float, float]      # cycle, PWM left, right, speed, x, y


def stop_bound(speed: float, watchdog: bool = True) -> float:
    """The longest it may take, from the moment the board last heard the host (or
    reset), until PWM is 0 for good at ``speed`` m/s: the watchdog and its latency of
    up to two ticks (not after a reset), braking from the wheels' speed at the gentler
    of the emergency deceleration and the hardest the motors brake
    (``ChairParams.max_braking``: docs/safety.md), and two control ticks (the one that
    sees the wheels slow enough, the one that parks)."""
    return ((WATCHDOG_S + 2 * PERIOD_S if watchdog else 0.0) + speed / _braking() + 2 * PERIOD_S)


def _braking() -> float:
    """m/s^2: the braking the stop can achieve (docs/safety.md)."""
    from wcdrive.plant import ChairParams

    return min(EMERGENCY_DECEL * WHEEL_RADIUS, ChairParams().max_braking)


def travel_bound(speed: float, watchdog: bool = True) -> float:
    """Issue 13's goal for the distance after the last byte: constant speed over the
    watchdog time (not after a reset), the braking distance at the emergency
    deceleration, plus 0.1 m."""
    return ((speed * (WATCHDOG_S + 2 * PERIOD_S) if watchdog else 0.0) + speed * speed / (2 * _braking())
            + 0.1)


class MegaCable(FaultyPort):
    """The USB cable between a host and a live ``MegaBoard`` (a ``wcavr://`` port), a
    ``FaultyPort`` (``cut(partial=True)``: the bytes are lost both ways while the port
    stays open, the write under way cut after a random number of its bytes;
    ``unplug()``: reads, writes and reopening raise ``SerialException`` until
    ``replug()``). Closing the host's end leaves the board running; opening it again
    (``reopen``) pulses DTR, which resets the board, as on a real Mega. ``board_tx``:
    every byte of the board that reached the cable (what the port read from the
    board), delivered or not; ``delivered``: those the host got."""

    def __init__(self, port: Port, rng: random.Random) -> None:
        super().__init__(port, seed=rng)
        self.board_tx = bytearray()
        self.delivered = bytearray()
        self._host_open = True

    def on_read(self, data: bytes) -> bytes:
        """Keeps every byte in ``board_tx`` and what passes the faults in ``delivered``."""
        out = super().on_read(data)
        with self._lock:
            self.board_tx += data
            self.delivered += out
        return out

    def _check(self) -> None:
        super()._check()
        if not self._host_open:
            raise serial.PortNotOpenError()

    def _drain(self) -> None:
        """What the board sent while the host's end was closed: kept, not delivered."""
        with self._lock:
            waiting = self.port.in_waiting
            self.board_tx += self.port.read(waiting) if waiting else b""

    @property
    def is_open(self) -> bool:
        """Whether the host's end is open."""
        return self._host_open

    def close(self) -> None:
        """Closes the host's end (the board runs on)."""
        self._host_open = False

    def reopen(self) -> MegaCable:
        """Opens the host's end again (``Session``'s reopen): raises while unplugged;
        else pulses DTR, which resets the board."""
        if self.unplugged:
            raise serial.SerialException("[Errno 2] could not open port: No such file or directory")
        self._drain()
        self._host_open = True
        self.port.board.reset("external")       # the wcavr:// port's MegaBoard
        return self

    def shutdown(self) -> None:
        """Closes the port to the board, and so the board."""
        self._drain()
        self.port.close()


@dataclass
class R3Trial:
    """One fault mid-motion. Board times are simulated seconds from the fault, host
    times wall seconds from the fault (``recovered_s``: from the end of the outage, or
    from the reset); None: never (within the trial)."""

    kind: str
    speed: float                        # commanded, m/s
    bound_s: float                      # stop_bound(speed), no watchdog for a reset
    travel_bound_m: float               # travel_bound(speed), likewise
    pwm_before: tuple[int, int] = (0, 0)
    pwm_after: tuple[int, int] = (0, 0)  # right after the fault (a reset: its first instruction)
    pwm_zero_s: float | None = None     # both PWM 0 for good (to the end of the outage)
    standstill_s: float | None = None   # the chair's speed below 0.01 m/s for good
    travel_m: float = 0.0
    noticed_s: float | None = None      # the host: LinkLost, a refused motion call, or BOARD_RESET
    noticed_by: str = ""
    #: the host drives again: a motion call passes once the board confirmed neutral (after a
    #: replug, hello answered again first); a DTR reset: hello answered again (None when it
    #: never drove again after it)
    recovered_s: float | None = None
    rehandshake: bool = False           # hello answered again after the fault
    boot_cause: str = ""                # as the host reported it (BOARD_RESET,<cause>), or its BOOT line
    executed_before_hello: int = 0      # frames the board executed after its reset, before a new hello
    link_losses_before: int = 0         # LinkLost while driving, before the fault (the board lagged)

    def stopped_in_time(self) -> bool:
        """PWM 0 for good within the bound; after a reset, PWM 0 from its first
        instruction (issue 14: "PWM reaches 0"). The fresh firmware then finds the chair
        still rolling and brakes it under its PID, setpoint 0, until it has been still
        for 3 ticks: ``pwm_zero_s`` reports that, and it is not a drive."""
        if self.kind == "DTR reset":
            return self.pwm_after == (0, 0)
        return self.pwm_zero_s is not None and self.pwm_zero_s <= self.bound_s


@dataclass
class R3Result:
    """R3: the trials of each kind, the frames the board executed (ACKed) and those
    executed twice, and how well the board kept to real time."""

    trials: dict[str, list[R3Trial]] = field(default_factory=dict)
    acked: int = 0
    executed_twice: list[int] = field(default_factory=list)
    board_lag_s: float = 0.0            # the most simulated time fell behind the (paced) wall clock
    pace: float = 1.0                   # simulated seconds per wall second
    examples: list[str] = field(default_factory=list)


class _Probe:
    """``MegaBoard.on_step``: a ``Sample`` at each step, since when the chair has been
    still and unpowered, and how far simulated time fell behind the wall clock."""

    def __init__(self, board: MegaBoard) -> None:
        self.board = board
        self.samples: list[Sample] = []
        self.cycle = 0
        self.quiet_since: int | None = None
        self.wall0: float | None = None
        self.lag = 0.0

    def __call__(self, tx: list[tuple[int, int]]) -> None:
        from wcdrive.avr.timer0 import F_CPU

        mega, plant = self.board.mega, self.board.plant
        assert plant is not None
        forward, lateral = plant.axle_velocity()
        x, y, _ = plant.pose
        sample = (mega.cycle, mega.pwm("left"), mega.pwm("right"), math.hypot(forward, lateral), x, y)
        self.samples.append(sample)
        self.cycle = sample[0]
        if sample[1] == 0 and sample[2] == 0 and sample[3] < STANDSTILL_MPS:
            if self.quiet_since is None:
                self.quiet_since = sample[0]
        else:
            self.quiet_since = None
        now = time.monotonic() * self.board.speed
        if self.wall0 is None:
            self.wall0 = now - sample[0] / F_CPU
        self.lag = max(self.lag, now - self.wall0 - sample[0] / F_CPU)

    def quiet_for(self) -> float:
        """Simulated seconds for which PWM has been 0 and the chair still."""
        from wcdrive.avr.timer0 import F_CPU

        since = self.quiet_since
        return 0.0 if since is None else (self.cycle - since) / F_CPU


def analyse_stop(samples: list[Sample], fault_cycle: int, end_cycle: int
                 ) -> tuple[float | None, float | None, float]:
    """From the probe's samples between the fault and the end of the outage: PWM 0 for
    good and standstill for good, each in s after the fault (None: not by the end),
    and the distance the chair travelled."""
    from wcdrive.avr.timer0 import F_CPU

    pwm_zero: float | None = 0.0
    still: float | None = 0.0
    travel = 0.0
    previous: tuple[float, float] | None = None
    seen = False
    for cycle, left, right, speed, x, y in samples:
        if not fault_cycle <= cycle <= end_cycle:
            continue
        seen = True
        t = (cycle - fault_cycle) / F_CPU
        if left or right:
            pwm_zero = None
        elif pwm_zero is None:
            pwm_zero = t
        if speed >= STANDSTILL_MPS:
            still = None
        elif still is None:
            still = t
        if previous is not None:
            travel += math.hypot(x - previous[0], y - previous[1])
        previous = (x, y)
    if not seen:
        return None, None, 0.0
    return pwm_zero, still, travel


def executed_before_hello(board_tx: bytes) -> int:
    """Frames a board executed (``ACK:``) after its ``BOOT:`` line and before it answered
    a new hello (the ACK of the hello itself aside): what it took while lax, with the
    host unaware of the reset."""
    boot = board_tx.find(b"BOOT:")
    if boot < 0:
        return 0
    after = board_tx[boot:]
    hello = after.find(b"HELLO:")
    return len(_ACK.findall(after if hello < 0 else after[:hello]))


class _Rig:
    """The firmware in simavr with the chair on its pins, at real time (times ``pace``),
    behind a ``MegaCable``, driven by a ``Wheelchair`` as a program would, whose
    link timeout is stretched by 1 / ``pace`` too: after the handshake it sends the
    neutral prelude (``wait_for_neutral``, as ``connect`` does)."""

    def __init__(self, elf: ElfPath, rng: random.Random, pace: float = 1.0) -> None:
        from wcdrive.host.wheelchair import LINK_TIMEOUT, Wheelchair

        self.pace = pace
        port = serial.serial_for_url(f"wcavr://{elf or ''}?speed={pace}", timeout=0.05)
        self.board: MegaBoard = port.board
        self.probe = _Probe(self.board)
        with self.board._lock:
            self.board.on_step = self.probe
        self.link = MegaCable(port, rng)
        self.link_events: list[tuple[float, object]] = []
        self.errors: list[str] = []
        self.chair = Wheelchair(self.link, name="wcavr-r3", reopen=self.link.reopen,
                                reconnect_timeout=30.0, stop_on_signals=False,
                                link_timeout=LINK_TIMEOUT / pace)
        self.chair.on_link(lambda event: self.link_events.append((time.monotonic(), event)))
        self.chair.wait_for_handshake(10.0)
        self.chair.wait_for_neutral(NEUTRAL_TIMEOUT_S / pace)

    def close(self) -> None:
        try:
            self.chair.close()
        finally:
            self.link.shutdown()


def _r3_trial(rig: _Rig, kind: str, rng: random.Random) -> R3Trial:
    """Drives at a random speed for 0.6-1.0 s, then the fault at a random moment
    between two commands; the host keeps commanding until it notices, then waits until
    the chair has stopped; then the link comes back (replugged: a DTR reset on open)
    and the host must drive again: once the link is back (after a reset or a replug:
    once hello was answered again) it sends stops until the board confirms neutral
    (``wait_for_neutral``: the board refuses motion after a reset or a watchdog stop of
    motion until then, and a program must do so itself), then a motion call must pass."""
    from wcdrive.errors import WcdriveError
    from wcdrive.host.telemetry import LinkLost

    chair, link, board = rig.chair, rig.link, rig.board
    period, stretch = HOST_PERIOD_S / rig.pace, 1.0 / rig.pace      # in wall seconds
    speed = rng.uniform(0.4, 1.2)
    watchdog = kind != "DTR reset"
    trial = R3Trial(kind, speed, stop_bound(speed, watchdog), travel_bound(speed, watchdog))
    links_start = len(rig.link_events)
    t_stop = time.monotonic() + rng.uniform(0.6, 1.0) * stretch
    while True:
        t_last = time.monotonic()
        try:
            chair.set_velocity(speed, 0.0)
        except WcdriveError as exc:
            rig.errors.append(f"{kind}: a motion call before the fault failed: {exc}")
        if t_last + period >= t_stop:
            break
        time.sleep(max(0.0, t_last + period - time.monotonic()))
    time.sleep(max(0.0, t_last + rng.uniform(0.0, period) - time.monotonic()))
    events0, links0, errors0 = len(chair.events), len(rig.link_events), len(chair.errors)
    hellos0, delivered0, tx0 = link.delivered.count(b"HELLO:"), len(link.delivered), len(link.board_tx)
    trial.link_losses_before = sum(isinstance(e, LinkLost) for _, e in rig.link_events[links_start:links0])

    def fault(mega: VirtualMega) -> tuple[int, tuple[int, int], tuple[int, int]]:
        before = (mega.pwm("left"), mega.pwm("right"))
        if kind == "link cut":
            link.cut(partial=True)
        elif kind == "unplug":
            link.unplug()
        else:
            mega.reset("external")
        return mega.cycle, before, (mega.pwm("left"), mega.pwm("right"))

    def ready() -> bool:
        hello_again = link.delivered.count(b"HELLO:") > hellos0
        trial.rehandshake = hello_again
        return (chair.link_ok and chair.protocol_version == integer("PROTOCOL_VERSION")
                and (kind == "link cut" or hello_again))

    t_fault = time.monotonic()
    fault_cycle, trial.pwm_before, trial.pwm_after = board.between_steps(fault)
    # The host: a command every 50 ms until it notices (a refused call, LinkLost,
    # BOARD_RESET), then none. The outage lasts until the chair has been still and
    # unpowered for 0.1 s (at least 0.3 s, at most 2.5 s past the stop bound).
    next_command = t_last + period
    min_end, max_end = t_fault + 0.3 * stretch, t_fault + (stop_bound(speed) + 2.5) * stretch
    while time.monotonic() < max_end:
        now = time.monotonic()
        if trial.noticed_s is None:
            lost = [t for t, e in rig.link_events[links0:] if isinstance(e, LinkLost)]
            resets = [e for e in chair.events[events0:] if e.startswith("BOARD_RESET")]
            if lost:
                trial.noticed_s, trial.noticed_by = (lost[0] - t_fault) * rig.pace, "LinkLost"
            elif resets:
                trial.noticed_s, trial.noticed_by = (now - t_fault) * rig.pace, "BOOT"
                trial.boot_cause = resets[0].partition(",")[2]
            elif now >= next_command:
                next_command += period
                try:
                    chair.set_velocity(speed, 0.0)
                except WcdriveError:
                    trial.noticed_s, trial.noticed_by = (now - t_fault) * rig.pace, "refused"
        elif now >= min_end and rig.probe.quiet_for() >= 0.1:
            break
        if kind == "DTR reset" and trial.recovered_s is None and ready():
            trial.recovered_s = (now - t_fault) * rig.pace
        time.sleep(0.005)
    end_cycle = board.between_steps(lambda mega: mega.cycle)
    if kind == "link cut":
        link.restore()
    elif kind == "unplug":
        link.replug()
    t_back = time.monotonic()
    deadline = t_back + RECOVERY_TIMEOUT_S * stretch
    while time.monotonic() < deadline:
        if ready():
            try:
                chair.wait_for_neutral(max(0.05 * stretch, deadline - time.monotonic()))
                chair.set_velocity(0.0, 0.0)
            except WcdriveError:
                pass
            else:
                if trial.recovered_s is None and kind != "DTR reset":
                    trial.recovered_s = (time.monotonic() - t_back) * rig.pace
                break
        time.sleep(0.005)
    else:
        trial.recovered_s = None
    got = bytes(link.delivered[delivered0:])
    boots = _BOOT.findall(got)
    if not trial.boot_cause and boots:          # a replug: its BOOT line came before hello
        trial.boot_cause = boots[0].decode()
    if kind == "DTR reset" and trial.noticed_s is None and boots:
        whole = bytes(link.delivered)               # the line may have begun before the fault
        at = whole.find(b"BOOT:", delivered0)
        line = whole[whole.rfind(b"\n", 0, at) + 1:whole.find(b"\n", at) + 1]
        rig.errors.append(f"{kind}: the host got {line!r} and did not see the reset")
    elif kind != "link cut" and trial.noticed_s is not None and not trial.rehandshake:
        rig.errors.append(f"{kind}: the host saw the reset and said hello, but got "
                          f"{['ERR:' + e for e in chair.errors[errors0:]]} and no HELLO; "
                          f"protocol_version {chair.protocol_version}")
    trial.executed_before_hello = executed_before_hello(bytes(link.board_tx[tx0:]))
    trial.pwm_zero_s, trial.standstill_s, trial.travel_m = analyse_stop(rig.probe.samples,
                                                                        fault_cycle, end_cycle)
    del rig.probe.samples[:-1]
    return trial


def firmware_r3(trials: int, rng: random.Random, elf: ElfPath, log: bool = False,
                pace: float = 1.0) -> R3Result:
    """R3: ``trials`` of each kind (link cut, unplug, DTR reset), mixed in a random
    order, on one live board at real time behind a ``MegaCable``, driven by a
    ``Wheelchair``. Each time the chair must stop (PWM 0 within ``stop_bound``; after
    a reset also at its first instruction), the host must notice and drive again
    (after a reset or a replug: after a new hello), and no frame is executed twice.
    ``pace`` < 1 runs the board slower than real time, and the host's clock with it
    (its command period and link timeout), for a loaded machine: host times are
    reported in the board's seconds."""
    res = R3Result(trials={k: [] for k in R3_KINDS}, pace=pace)
    order = [k for k in R3_KINDS for _ in range(trials)]
    rng.shuffle(order)
    acks: Counter[int] = Counter()

    def finish(rig: _Rig) -> None:
        rig.close()
        acks.update(int(s) for s in _ACK.findall(bytes(rig.link.board_tx)))
        res.acked += sum(acks.values())
        res.executed_twice += sorted(s for s, n in acks.items() if n > 1)
        res.board_lag_s = max(res.board_lag_s, rig.probe.lag)
        res.examples.extend(rig.errors)
        acks.clear()

    rig = _Rig(elf, rng, pace)
    try:
        for i, kind in enumerate(order):
            trial = _r3_trial(rig, kind, rng)
            res.trials[kind].append(trial)
            if log and (i + 1) % 30 == 0:
                print(f"    R3 {i + 1}/{len(order)}", file=sys.stderr, flush=True)
            if trial.recovered_s is None:           # a host that never came back: start again
                res.examples.append(f"trial {i + 1} ({kind}): the host never drove again; "
                                    "a new board and host for the next")
                finish(rig)
                rig = _Rig(elf, rng, pace)
    finally:
        finish(rig)
    return res


def r3_problems(r: R3Result) -> list[str]:
    """What R3 found wrong, by kind (empty: every trial as required)."""
    found = []
    for kind, trials in r.trials.items():
        bad = {
            "trials not in motion at the fault": sum(t.pwm_before == (0, 0) for t in trials),
            "stops late or never (PWM)": sum(not t.stopped_in_time() for t in trials),
            "faults the host did not notice": sum(t.noticed_s is None for t in trials),
            "hosts that never drove again": sum(t.recovered_s is None for t in trials),
        }
        if kind != "link cut":
            bad["re-handshakes missing"] = sum(not t.rehandshake for t in trials)
            bad["reboots without the cause EXTERNAL"] = sum(t.boot_cause != "EXTERNAL" for t in trials)
        found += [f"R3 {kind}: {v} {k}" for k, v in bad.items() if v]
    if r.executed_twice:
        found.append(f"R3: sequence numbers executed twice: {r.executed_twice[:10]}")
    return found + [f"  {e}" for e in r.examples[:10]]


