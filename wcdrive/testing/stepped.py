"""``SteppedChair``: the bit-exact port driving the pymunk plant, advanced by the caller.

No thread and no wall clock: ``run(seconds)`` advances simulated time, so a test is
deterministic and as fast as the port runs (a few hundred times real time)::

    chair = SteppedChair()
    chair.set_velocity(0.3, 0.0)      # a CMDVEL line onto the simulated wire
    chair.run(1.0)                    # one simulated second
    x, y, heading = chair.pose        # the plant's ground truth
"""

from __future__ import annotations

import warnings
from collections import deque
from collections.abc import Sequence

from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.faults import Fault
from wcdrive.plant.params import ChairParams
from wcdrive.protocol.codec import (
    SEQ_MAX,
    Event,
    Feedback,
    LineDecoder,
    Message,
    frame,
)
from wcdrive.protocol.motion import velocity_command, wheel_command

#: How many of the board's messages ``SteppedChair.messages`` keeps (the newest).
MESSAGE_HISTORY = 10_000


class SteppedChair:
    """The port (``wcdrive.firmware``) and the plant in one ``PortLoop``, stepped by
    ``run``. ``faults`` (``wcdrive.plant.faults.Fault``) are injected as a scenario's
    ``[[fault]]`` entries are; ``seed`` seeds the gyro."""

    def __init__(self, params: ChairParams | None = None, *, faults: Sequence[Fault] = (),
                 seed: int = 0, dt: float = 0.001, history: int = MESSAGE_HISTORY) -> None:
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
        self._seq = 0

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

    def command(self, body: bytes) -> None:
        """``body`` (``x:0.300,t:0.000,``, ``hello``, ``reset``, ``set:kp=2`` ...) as a
        protocol v3 frame with the next sequence number, as ``Wheelchair`` sends it:
        the board takes it before and after a ``hello``."""
        self._seq = self._seq % SEQ_MAX + 1
        self.send(frame(body, self._seq))

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
        for _, data in self.loop.take_output():
            out += self._decoder.feed(data)
        for msg in out:
            if isinstance(msg, Feedback):
                self.feedback = msg
            elif isinstance(msg, Event):
                self.events.append(msg.name)
        self.messages.extend(out)
        return out
