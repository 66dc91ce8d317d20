"""The pymunk chair wired to the simulated Mega's pins: the one step that both the live
board (``MegaBoard``) and ``wcdrive sim --backend simavr`` take.

Per physics step: the plant advances, the wheels' motion over the step becomes
encoder edges queued on the encoder pins, the battery's terminal voltage over the step
goes on the supply sense (A0, from the step's start), the firmware runs through the
step, and its PWM and DIR pins drive the plant over the next one.

Faults (``wcdrive.plant.faults``, given as ``faults=``): the encoder kinds act on the
wires (``EncoderWire``: a cut queues no more edges, a reversal swaps the two bits of
every state queued, noise merges its chatter into the train, which can be millions of
edges, queued a step at a time); wheel and motor faults act on the plant from the step
at which they start; a ``reset`` resets the Mega (``VirtualMega.reset``) at its cycle,
within the step.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from wcdrive.avr.timer0 import F_CPU
from wcdrive.boards.current_sense import CURRENT_CHANNELS, plant_current_millivolts
from wcdrive.boards.port_loop import advance
from wcdrive.boards.simavr.mega_pins import BRAKE_STATUS_PIN, PUSH_PIN
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.boards.supply_sense import SUPPLY_CHANNEL, plant_millivolts
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.plant.faults import PLANT_KINDS, EncoderWire, Fault, apply_plant_faults

__all__ = ["PlantOnPins"]

SIDES = ("left", "right")


class PlantOnPins:
    """``plant`` behind ``mega``'s pins; ``gyro`` (optional) samples the plant's yaw rate;
    ``faults`` are injected as the module docstring says."""

    def __init__(self, mega: VirtualMega, plant: Plant, gyro: Gyro | None = None,
                 faults: Sequence[Fault] = (), levers: Sequence[tuple[int, bool]] = ()) -> None:
        self.mega = mega
        self.plant = plant
        self.gyro = gyro
        self.faults = tuple(faults)
        self._scale = plant.p.counts_per_rev / (2.0 * math.pi)
        self._position = {"left": 0.5, "right": 0.5}     # counts; floor() is the count
        wires = {side: EncoderWire(self.faults, side, F_CPU) for side in SIDES}
        self._wires = {side: w for side, w in wires.items() if w.faulty}
        self._plant_faults = any(f.kind in PLANT_KINDS for f in self.faults)
        self._resets = sorted(f.cycles(F_CPU)[0] for f in self.faults if f.kind == "reset")
        #: The brake's manual-release lever: (cycle, pulled), applied to the plant at the
        #: step that starts at or after it.
        self._levers = sorted(levers)
        #: The pins the plant drives as it set them: the brake driver's status (s, 3, LOW)
        #: and the lever's switch (s, 4, LOW), inputs 3 and 4 of a lock-step trace
        #: (``wcdrive.boards.simavr.mega_pins.INPUT_PINS``).
        self.input_changes: list[tuple[float, int, bool]] = []
        #: The millivolts put on the supply sense (A0) as they changed: (s, mV), the
        #: lock-step trace's ``supply``; the board starts at ``NOMINAL_MV``. Kept while
        #: ``mega.keep_records`` (a live board's battery would log a change a step).
        self.supply_changes: list[tuple[float, int]] = []
        #: ...and on the motors' current senses (A1, A2): (s, side, mV), the trace's
        #: ``currents``; the board starts at 0 A (``current_sense.ZERO_MV``).
        self.current_changes: list[tuple[float, str, int]] = []

    def step(self, t0: float, t1: float, run_until: Callable[[int], None] | None = None,
             reset: Callable[[], object] | None = None) -> dict[str, EdgeTrain]:
        """One physics step over [t0, t1] s of simulated time (the Mega is at ``t0``):
        returns the edges queued on each encoder. ``run_until`` runs the Mega to a cycle
        and ``reset`` resets it (default ``mega.run_until``, ``mega.reset``; the
        lock-step recorder passes its own)."""
        c0, c1 = round(t0 * F_CPU), round(t1 * F_CPU)
        if self._plant_faults:
            apply_plant_faults(self.plant, self.faults, c0, F_CPU)
        while self._levers and self._levers[0][0] <= c0:
            self.plant.set_brake_lever(self._levers.pop(0)[1])
        angles = advance(self.plant, self.gyro, 1, t1 - t0)
        assert angles is not None
        new = {"left": -angles[0, 0] * self._scale + 0.5, "right": angles[0, 1] * self._scale + 0.5}
        trains = {}
        for side in SIDES:
            train = edges_from_trajectory(np.array([t0, t1]), np.array([self._position[side], new[side]]))
            wire = self._wires.get(side)
            if wire is not None:
                ticks = np.clip(np.round(train.times * F_CPU).astype(np.int64), c0 + 1, c1)
                ticks, states = wire.transform(c0, c1, ticks, train.states)
                train = EdgeTrain(ticks / F_CPU, states, train.start_count, train.end_count)
            if train.times.size:
                self.mega.encoder_edges(side, train)
            trains[side] = train
            self._position[side] = new[side]
        self._supply(c0)
        run = run_until or self.mega.run_until
        while self._resets and self._resets[0] <= c1:
            cycle = self._resets.pop(0)
            run(cycle)
            (reset or self.mega.reset)()
        run(c1)
        self.plant.set_drive(self.mega.pwm("left"), self.mega.direction("left"),
                             self.mega.pwm("right"), self.mega.direction("right"))
        self.plant.set_brake(bool(self.mega.brake_released()))
        for number, pin, low in ((3, BRAKE_STATUS_PIN, self.plant.brake_status_low),
                                 (4, PUSH_PIN, self.plant.brake_lever)):
            if self.mega.pin_level(pin) != (0 if low else 1):
                self.mega.set_pin(pin, 0 if low else 1)
                self.input_changes.append((self.mega.cycle / F_CPU, number, low))
        return trains

    def _supply(self, c0: int) -> None:
        """The battery's terminal voltage over the step just taken onto A0 from the
        step's start ``c0``, when its millivolts changed: a tick in the step reads the
        voltage of the step it runs in. (The port's tick reads the plant's voltage as
        the plant last computed it too, ``PortLoop``: there the step before the tick.)"""
        mv = plant_millivolts(self.plant)
        if mv != self.mega.analog(SUPPLY_CHANNEL):
            self.mega.set_analog(SUPPLY_CHANNEL, mv, at=c0)
            if self.mega.keep_records:
                self.supply_changes.append((c0 / F_CPU, mv))
        # the motors' currents too (the ADC interrupt reads them after a tick begins)
        for side, mv in plant_current_millivolts(self.plant).items():
            channel = CURRENT_CHANNELS[side]
            if mv != self.mega.analog(channel):
                self.mega.set_analog(channel, mv, at=c0)
                if self.mega.keep_records:
                    self.current_changes.append((c0 / F_CPU, side, mv))
