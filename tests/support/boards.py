"""Helpers for tests that drive the virtual Mega."""

from __future__ import annotations

import re

from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega

FEEDBACK = re.compile(rb"ENC:(-?\d+),(-?\d+),VEL:(-?[\d.]+|nan|inf|ovf),(-?[\d.]+|nan|inf|ovf),"
                      rb"MODE:(WHEEL|CMDVEL|PPM)\r\n")


def boot(mega: VirtualMega, seconds: float = 0.06) -> bytes:
    """Runs past setup() and the first tick; returns what the board sent."""
    mega.run_for(seconds)
    return bytes(b for _, b in mega.take_tx())


def send_and_run(mega: VirtualMega, data: bytes, seconds: float) -> bytes:
    mega.send(data)
    mega.run_for(seconds)
    return bytes(b for _, b in mega.take_tx())


#: A neutral (zero) command, as every host sends first: after a boot (and a reset that
#: released an e-stop or a fault, a watchdog stop of motion, a PPM loss) the board
#: refuses motion (``ERR:neutral``) until a neutral command has stood ``NEUTRAL_TICKS``
#: (2) control ticks with no motion command after it (protocol/PROTOCOL.md, "Neutral
#: before motion").
NEUTRAL = b"rp0,lp0,\n"
#: The same for a PPM host: both sticks at centre.
NEUTRAL_PPM = b"ppm:1500,1500,1500,1500,1500,1500,1500,1500,\n"
#: Board time a neutral command is left to stand: NEUTRAL_TICKS ticks of 50 ms, wherever
#: between two ticks it arrived, and a margin (3 ticks).
NEUTRAL_WAIT = 0.12


def neutral(mega: VirtualMega, command: bytes = NEUTRAL, seconds: float = NEUTRAL_WAIT) -> bytes:
    """Sends a neutral command and runs ``seconds`` (it stands: the board drives the next
    motion command); returns what the board sent."""
    return send_and_run(mega, command, seconds)


def ms(cycles: int) -> float:
    return cycles * 1000.0 / F_CPU


class ChairOnPins:
    """A ``VirtualMega`` with the pymunk chair on its pins (``PlantOnPins``), stepped a
    millisecond at a time: the board's encoders see the wheels its motors turn, as on
    the real chair (a board driven with idle encoders latches a stall fault)."""

    def __init__(self, mega: VirtualMega, dt: float = 0.001, **chair: float) -> None:
        import dataclasses

        from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
        from wcdrive.plant import ChairParams, Plant

        self.mega = mega
        self.plant = Plant(dataclasses.replace(ChairParams(), **chair))  # type: ignore[arg-type]
        self.pins = PlantOnPins(mega, self.plant)
        self.dt = dt

    def run_for(self, seconds: float) -> None:
        """Runs the board and the chair for ``seconds``."""
        end = self.mega.time + seconds
        while self.mega.time < end - 1e-9:
            t0 = self.mega.time
            self.pins.step(t0, min(t0 + self.dt, end))

    def send_and_run(self, data: bytes, seconds: float) -> bytes:
        """Sends ``data``, runs for ``seconds``; returns what the board sent."""
        self.mega.send(data)
        self.run_for(seconds)
        return bytes(b for _, b in self.mega.take_tx())

    def neutral(self, command: bytes = NEUTRAL, seconds: float = NEUTRAL_WAIT) -> bytes:
        """``neutral`` with the chair on the pins."""
        return self.send_and_run(command, seconds)

    def speeds(self) -> tuple[float, float]:
        """The wheels' true speeds (rad/s, forward positive)."""
        return self.plant.left.speed, self.plant.right.speed
