"""Differential proof: the Python port against the compiled firmware in simavr.

``record(trace)`` runs the trace on the virtual Mega and stops at the entry of every
``processByte`` and ``controlTick`` call. Each stop gives one firmware event (the
byte, or the tick's ``millis()``) and the controller state the previous event left,
read from SRAM by symbol, with PWM and DIR from the I/O registers.

``compare(recording)`` feeds the same events to
``wcdrive.firmware.final_control.Firmware``, started in the port's boot state with the
firmware's ``lastControlTime``, and compares after every event: every controller float
bit for bit, every integer and flag, PWM duty and DIR per motor, the EEPROM, and, at
the end, the whole TX byte stream; every byte the host sent must reach the firmware's
parser or be lost where the firmware saw the loss, and the firmware must keep
ticking. Resets (``VirtualMega.reset``, or the watchdog) are followed boot by boot.
What it finds is a ``Report`` of ``Mismatch`` records.

This module is the harness's one name for the proof; the parts live apart, each with
its reasoning: ``lockstep_recording`` (``Event``, ``Recording``, ``Recorder``,
``record``: the stepping), ``lockstep_comparison`` (``compare``, ``initial_state``: the
replay on the port), ``lockstep_liveness`` (the bytes' delivery and the tick's stalls)
and ``lockstep_report`` (``Mismatch``, ``Report``). Import them from here.
"""

from __future__ import annotations

from wcdrive.hil.lockstep_comparison import compare, initial_state
from wcdrive.hil.lockstep_liveness import MILLIS_TOLERANCE_MS, TICK_TOLERANCE_MS
from wcdrive.hil.lockstep_recording import FINISH_S, Event, Recorder, Recording, record
from wcdrive.hil.lockstep_report import Mismatch, Report

__all__ = ["FINISH_S", "MILLIS_TOLERANCE_MS", "TICK_TOLERANCE_MS", "Event", "Mismatch", "Recorder",
           "Recording", "Report", "compare", "initial_state", "record"]
