"""The pymunk chair wired to the simulated Mega's pins: the one step that both the live
board (``MegaBoard``) and ``wcdrive sim --backend simavr`` take.

Per physics step: the plant advances, the wheels' motion over the step becomes
encoder edges queued on the encoder pins, the firmware runs through the step, and its
PWM and DIR pins drive the plant over the next one.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from wcdrive.avr.timer0 import F_CPU
from wcdrive.boards.port_loop import advance
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory

__all__ = ["PlantOnPins"]

SIDES = ("left", "right")


class PlantOnPins:
    """``plant`` behind ``mega``'s pins; ``gyro`` (optional) samples the plant's yaw rate."""

    def __init__(self, mega: VirtualMega, plant: Plant, gyro: Gyro | None = None) -> None:
        self.mega = mega
        self.plant = plant
        self.gyro = gyro
        self._scale = plant.p.counts_per_rev / (2.0 * math.pi)
        self._position = {"left": 0.5, "right": 0.5}     # counts; floor() is the count

    def step(self, t0: float, t1: float, run_until: Callable[[int], None] | None = None
             ) -> dict[str, EdgeTrain]:
        """One physics step over [t0, t1] s of simulated time (the Mega is at ``t0``):
        returns the edges queued on each encoder. ``run_until`` runs the Mega to a cycle
        (default ``mega.run_until``; the lock-step recorder passes its own)."""
        angles = advance(self.plant, self.gyro, 1, t1 - t0)
        assert angles is not None
        new = {"left": -angles[0, 0] * self._scale + 0.5, "right": angles[0, 1] * self._scale + 0.5}
        trains = {}
        for side in SIDES:
            train = edges_from_trajectory(np.array([t0, t1]), np.array([self._position[side], new[side]]))
            if train.times.size:
                self.mega.encoder_edges(side, train)
            trains[side] = train
            self._position[side] = new[side]
        (run_until or self.mega.run_until)(round(t1 * F_CPU))
        self.plant.set_drive(self.mega.pwm("left"), self.mega.direction("left"),
                             self.mega.pwm("right"), self.mega.direction("right"))
        return trains
