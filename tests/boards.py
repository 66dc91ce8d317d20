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


def ms(cycles: int) -> float:
    return cycles * 1000.0 / F_CPU
