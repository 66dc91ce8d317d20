"""``SteppedChair``: the bit-exact port driving the pymunk plant, advanced by the caller.

No thread and no wall clock: ``run(seconds)`` advances simulated time, so a test is
deterministic and as fast as the port runs (a few hundred times real time)::

    chair = SteppedChair()
    chair.set_velocity(0.3, 0.0)      # a CMDVEL line onto the simulated wire
    chair.run(1.0)                    # one simulated second
    x, y, heading = chair.pose        # the plant's ground truth

It is a ``wcdrive.host.robot.Robot`` too, on simulated time: ``odometry`` is the
host's wheel odometry of the board's feedback (as ``Wheelchair``'s), ``telemetry(t)``
runs the simulation and yields each sample for ``t`` simulated seconds, and
``on_telemetry`` callbacks run as ``run`` delivers the samples. Navigation code
written against ``Robot`` runs on it unchanged, faster than real time and repeatably.
"""

from __future__ import annotations

import warnings
from collections import deque
from collections.abc import Callable, Iterator, Sequence

from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware import constants as C
from wcdrive.host.odometry import OdometryEstimate, WheelOdometry
from wcdrive.host.telemetry import Telemetry, chair_wheel_angles
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.faults import Fault
from wcdrive.plant.params import ChairParams
from wcdrive.protocol.codec import (
    MAX_ANGULAR,
    MAX_LINEAR,
    Event,
    Feedback,
    LineDecoder,
    Message,
)
from wcdrive.protocol.exchange import Exchange
from wcdrive.protocol.motion import velocity_command, wheel_command

#: How many of the board's messages ``SteppedChair.messages`` keeps (the newest).
MESSAGE_HISTORY = 10_000
#: How long a new ``SteppedChair`` runs after its neutral command: the board has
#: confirmed it (NEUTRAL_TICKS ticks) by then.
NEUTRAL_CONFIRM_S = (C.NEUTRAL_TICKS + 1) * C.CONTROL_PERIOD_MS / 1000.0


class SteppedChair:
    """The port (``wcdrive.firmware``) and the plant in one ``PortLoop``, stepped by
    ``run``. ``faults`` (``wcdrive.plant.faults.Fault``) are injected as a scenario's
    ``[[fault]]`` entries are; ``seed`` seeds the gyro. Like ``connect``, it starts with a
    neutral command and runs ``NEUTRAL_CONFIRM_S`` until the board has confirmed it (it
    drives only after one); ``neutral=False`` leaves the board waiting for one, at
    time 0."""

    def __init__(self, params: ChairParams | None = None, *, faults: Sequence[Fault] = (),
                 seed: int = 0, dt: float = 0.001, history: int = MESSAGE_HISTORY,
                 neutral: bool = True) -> None:
        self.params = params or ChairParams()
        self.plant = Plant(self.params)
        self.loop = PortLoop(self.plant, Gyro(self.params, seed), dt=dt, faults=faults)
        self._decoder = LineDecoder()
        #: The board's messages, oldest first (the newest ``history``).
        self.messages: deque[Message] = deque(maxlen=history)
        #: The ``EVT:`` names the board sent (``WATCHDOG``, ``FAULT,ENC_STALL_L``, ...).
        self.events: deque[str] = deque(maxlen=history)
        #: The last ``ENC:...`` feedback line (None before the first control tick).
        self.feedback: Feedback | None = None
        self._exchange = Exchange()
        self._odometry = WheelOdometry()
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self._samples: deque[Telemetry] = deque(maxlen=history)
        self._closed = False
        if neutral:
            self.stop()
            self.run(NEUTRAL_CONFIRM_S)

    @property
    def time(self) -> float:
        """Simulated seconds since boot."""
        return self.loop.cycle / F_CPU

    @property
    def pose(self) -> tuple[float, float, float]:
        """The plant's ground truth: x, y (m) and heading (rad)."""
        return self.plant.pose

    @property
    def pwm(self) -> tuple[int, int]:
        """The signed duties the firmware drives (left, right), -255..255."""
        s = self.loop.fw.state
        return (s.pwmL if s.dirL else -s.pwmL, s.pwmR if s.dirR else -s.pwmR)

    def send(self, data: bytes) -> None:
        """Raw bytes onto the board's RX wire, from now, at 115200 baud."""
        self.loop.send(data)

    @property
    def _seq(self) -> int:
        """The sequence number of the last frame sent (0 before the first)."""
        return self._exchange.last_seq

    def command(self, body: bytes) -> None:
        """``body`` (``x:0.300,t:0.000,``, ``hello``, ``reset``, ``set:kp=2`` ...) as a
        protocol v3 frame with the next sequence number, as ``Wheelchair`` sends it
        (numbered by the same ``wcdrive.protocol.exchange.Exchange``): the board takes
        it before and after a ``hello``."""
        self.send(self._exchange.next_frame(body)[1])

    def set_velocity(self, linear: float, angular: float) -> None:
        """A CMDVEL frame (m/s, rad/s), validated and encoded as ``Wheelchair`` sends it
        (``wcdrive.protocol.motion``); resend it at least every 500 ms (watchdog)."""
        self.command(velocity_command(linear, angular))

    def set_wheels(self, *args: float, left: float | None = None, right: float | None = None) -> None:
        """A WHEEL frame: ``set_wheels(left=..., right=...)`` in rad/s, validated and
        encoded as ``Wheelchair.set_wheels(left, right)`` sends it.

        Deprecated: positional arguments, which this class took as ``(right, left)``
        (the wire's order), the opposite of ``Wheelchair``. They keep that meaning for
        this release, with a ``DeprecationWarning``; pass the wheels by name. From the
        next release the positional order is ``(left, right)``, as ``Wheelchair``'s."""
        if args:
            if len(args) != 2 or left is not None or right is not None:
                raise TypeError("set_wheels takes left= and right= (by name)")
            warnings.warn("SteppedChair.set_wheels(right, left) by position is deprecated: its order "
                          "becomes (left, right), as Wheelchair.set_wheels', in the next release; "
                          "pass set_wheels(left=..., right=...)", DeprecationWarning, stacklevel=2)
            right, left = args
        if left is None or right is None:
            raise TypeError("set_wheels needs both left= and right=")
        self.command(wheel_command(left, right))

    def run(self, seconds: float) -> list[Message]:
        """Advances simulated time by ``seconds``; returns the board's messages."""
        if seconds < 0:
            raise ValueError("seconds must be >= 0")
        self.loop.run_until(self.loop.cycle + round(seconds * F_CPU))
        out: list[Message] = []
        for cycle, data in self.loop.take_output():
            messages = self._decoder.feed(data)
            for msg in messages:
                if isinstance(msg, Feedback):
                    self.feedback = msg
                    self._deliver(cycle / F_CPU, msg)
                elif isinstance(msg, Event):
                    self.events.append(msg.name)
            out += messages
        self.messages.extend(out)
        return out

    def _deliver(self, t: float, msg: Feedback) -> None:
        sample = Telemetry(t, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right, msg.mode,
                           board_time=t, stamp=t)
        self._odometry.integrate(t, msg.count_left, msg.count_right)
        self._samples.append(sample)
        for callback in tuple(self._callbacks):
            callback(sample)

    # ---- the Robot surface (wcdrive.host.robot.Robot), on simulated time ----------
    def stop(self) -> None:
        """Targets to zero at the normal ramp (a zero CMDVEL frame)."""
        self.set_velocity(0.0, 0.0)

    @property
    def odometry(self) -> OdometryEstimate:
        """The host's wheel odometry of the board's feedback, stamped in simulated s."""
        return self._odometry.estimate(self.time)

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        """Each sample, the simulation run on a control period at a time as the caller
        iterates; ends after ``timeout`` simulated seconds without one (as
        ``Wheelchair.telemetry`` ends after ``timeout`` s of silence), or on close."""
        step = C.CONTROL_PERIOD_MS / 1000.0
        self._samples.clear()
        quiet = 0.0
        while not self._closed:
            self.run(step)
            if not self._samples:
                quiet += step
                if timeout is not None and quiet >= timeout:
                    return
                continue
            quiet = 0.0
            while self._samples:
                yield self._samples.popleft()

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` with each sample as ``run`` delivers it."""
        self._callbacks.append(callback)

    @property
    def link_ok(self) -> bool:
        """True until ``close``: the stepped wire never drops."""
        return not self._closed

    def wheel_angles(self, sample: Telemetry) -> tuple[float, float]:
        """The wheels' angles (rad, forward positive): the left encoder counts mirrored."""
        return chair_wheel_angles(sample)

    @property
    def command_limits(self) -> tuple[float, float]:
        """The protocol's limits (m/s, rad/s)."""
        return MAX_LINEAR, MAX_ANGULAR

    def close(self) -> None:
        """Sends a stop and lets the chair come to rest (one simulated second)."""
        if self._closed:
            return
        self.stop()
        self.run(1.0)
        self._closed = True

    def __enter__(self) -> SteppedChair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
