"""Reliability benchmark for protocol v3: the Python port and the compiled
firmware in simavr take the same hostile input, and nothing but a valid command moves
the chair. docs/benchmarks.md ("Reliability (protocol v3)") keeps the figures.

    python benchmarks/reliability.py [--quick] [--seed N] [--no-simavr]
        [--port-lines N] [--port-frames N] [--legacy-frames N]
        [--firmware-lines N] [--firmware-frames N] [--r3-trials N] [--r3-pace X]

(or ``python -m benchmarks.reliability ...`` from the checkout). The modules:
``inputs`` (the hostile input), ``oracle`` (valid input, from the protocol),
``common`` (limits, run sizes, what a line did, result records), ``r1``, ``r2``
(with the v1/v2 comparison), ``r3``, ``report`` (markdown, problems) and ``runner``
(``run``, ``main``).

R1, random and mutated lines. Every line ends in ``\\n``, so each starts with an empty
command buffer. Sources: random bytes (30 %), mutations of valid commands (55 %: bit
flips, byte replacements, insertions, deletions, truncations, duplications, splices
of two commands, swapped bytes, toggled case and, after hello, a frame stripped to its
bare command), and valid commands as controls (15 %: motions, stops, PPM loss and,
after hello, get/set). 80 % of the lines go to a board that said hello (strict), 20 %
to one that did not (legacy, version 1). Each board first gets the neutral prelude a
host sends after boot (protocol/PROTOCOL.md, "Neutral before motion": after a boot the
board refuses motion until a neutral command has stood ``NEUTRAL_TICKS`` ticks): after
hello the stop ``Wheelchair.stop`` sends (seq 2), before hello the seed era's
``rp0.0,lp0.0,``; a board still waiting for neutral when the stream begins is a problem.

* Valid input, decided by an oracle written from protocol/PROTOCOL.md and not from the
  parser: the line is cut into commands by the rules of "Framing and commands" (a
  command ends at a line end, or at the comma of its last field unless it starts
  with ``$``; more than 63 bytes is overlong). After hello a line is valid when one
  of its commands is a v3 frame with the right CRC-16 (``$<1-5 digits>:<...>*<4 upper
  hex>``, seq <= 65535, at most 63 bytes). Before hello it is valid when one of its
  commands is a well-formed version-1 command (WHEEL, CMDVEL within range, PPM with
  eight 1-4 digit channels, hello, estop, reset, get:, set:) or such a frame. The
  oracle errs on the side of "valid" at the range limits (1e-6 relative).
* A motion from invalid input: a line the oracle calls invalid after which the chair
  is commanded to move (a non-zero wheel target, or a pivot under way) and the line
  either changed the commanded motion (mode, targets, pivot phase, pending targets)
  or was accepted as a command (``cmdSinceTick`` set, which re-arms the watchdog).
  Stops are not motions: after hello a bare ``x:0,t:0,`` or PPM loss frame is still
  accepted, by design. Parameter changes from invalid lines are counted too.
* Valid motions carried out: valid drives (controls) that drove (on the port after
  hello, also ``ACK``ed).
* Neutral before motion, where the stream itself begins a wait (a PPM loss frame; a
  watchdog stop of a motion, the watchdog time after the last accepted command: on the
  port 10 lines at the default 500 ms; an e-stop or fault released by ``reset``):
  whether the board waits is read from its state, ``needNeutral`` (on the port before
  and after each line, on the firmware in SRAM at each byte). A valid drive that the
  board refuses ``neutral`` while it waits is correctly refused (``refused_neutral``),
  not a motion not carried out: on the port its answer is ``ERR:neutral`` /
  ``NAK:<seq>,neutral``; on the firmware, at the byte that ends the command (a frame's
  line end, a bare command's last comma) the board waited, counted a refusal
  (``rejectedCount``) and restarted the wait (``notNeutralSent`` set, ``neutralSeen``
  clear). A line of any source that drove (as above) while the board
  waited, before or after the line (the firmware: the byte), is a motion while waiting
  for neutral (``neutral_motions``): a safety violation, and a problem. The waits the
  stream began are counted (``neutral_waits``).
* On the port every line is fed to ``Firmware.feed`` and a 50 ms tick follows it, so
  each line gets its answers (3 per tick) and ``cmdSinceTick`` starts at 0; the prelude
  is ticked until the board no longer waits (at most ``NEUTRAL_TICKS`` + 2 ticks). A
  crash is an exception (the board boots again, with its prelude); a hang a line that
  takes more than 50 ms (one control period).
* On the firmware the lines go in chunks, each on a freshly booted board in simavr, at
  wire speed (with a pause after 1 line in 20) after the prelude and ``NEUTRAL_WAIT_S``
  (0.2 s: what ``wcdrive.host.neutral`` waits for a board that reports no state),
  through ``wcdrive.hil.lockstep``:
  ``record`` stops at every ``processByte`` and ``controlTick`` (and finishes the
  event under way when the trace ends), ``compare`` feeds
  the same events to the port and compares every global after every event, PWM and
  DIR, and the whole TX stream (port = firmware). The motion check runs on the
  firmware's own SRAM after each byte. A crash is the AVR core stopping or a second
  BOOT line; a hang a byte that never reaches ``processByte`` or waits more than 50 ms
  for it, or a missed tick (two ticks 100 ms apart).

R2, corrupted frames: CMDVEL frames (random x/t, random seq) with 1, 2 or 3 flipped
bits, or a burst of 2 to 16 bits (first and last flipped, the middle random) counted
in the CRC's bit order (MSB first) or in the UART's (LSB first), anywhere in the line
but its final ``\\n`` (the ``$``, ``*``, CRC digits and seq included), sent after
hello and the neutral prelude (on the firmware ``NEUTRAL_WAIT_S`` before the frames; a
board still waiting for neutral then is a problem: it would refuse any frame). None may
be executed (any change of motion, parameters or e-stop, or an accepted command) or
ACKed, and every command they split into must be refused. For
comparison, the same corruptions of the bare v1 line ``x:...,t:...,\\n`` before
hello (what a seed host without hello risks), and of a v2 frame ``$seq:cmd*hh`` with
the XOR checksum, in a model: the port before hello with the CRC check replaced by
v2's (either-case hex XOR); v2 boards also took unframed lines after hello, as the
port takes them before. Each of these trials starts on a fresh board at rest after its
neutral prelude (``rp0.0,lp0.0,`` and ``NEUTRAL_TICKS`` ticks; a copy of one such board).

R3, faults mid-motion (``firmware_r3``): the firmware in simavr with the chair on its
pins (``MegaBoard``, paced to real time, or ``--r3-pace`` times it with the host's
clock stretched alike), behind a ``FaultyPort`` (the USB cable), driven by a
``Wheelchair`` (after its handshake, ``wait_for_neutral``, as ``connect`` does) with
``set_velocity`` at 20 Hz at 0.4-1.2 m/s for 0.6-1.0 s; then, at
a random moment between two commands, one of: the link cut both ways while the port
stays open (mid-line when a write is under way), the device unplugged (reads, writes
and reopening raise; replugged, opening the port pulses DTR and resets the board, as
on a real Mega), or a DTR reset (``MegaBoard.reset``). The host commands on until it
notices (``LinkLost``, a refused motion call, or ``BOARD_RESET``), then waits until the
chair has been still and unpowered for 0.1 s; the link comes back and the host must
drive again: once the link is back (after a reset or a replug: once the board answered
a new hello) it sends stops until the board confirms neutral (``wait_for_neutral``: after
a reset or a watchdog stop of motion the board refuses motion until then, and a program
must do this itself, protocol/PROTOCOL.md), then a motion call must pass. Per
trial: PWM 0 for good against ``stop_bound`` (the watchdog, the ramp at the emergency
deceleration, two ticks; after a reset no watchdog, and PWM 0 from its first
instruction), the standstill, the travel against issue 13's distance goal, when the
host noticed and drove again, the reboot cause it saw, and the frames the board
executed after a reset before a new hello; over the run, the frames executed twice
(an ``ACK:`` of one sequence number twice).
"""

from __future__ import annotations

from .common import FULL, QUICK, Legacy, Lockstep, R1Slice, R2Result
from .inputs import CORRUPTIONS, MUTATIONS, corrupt, mutate, r1_lines, random_line, valid_line
from .oracle import frame_valid, line_valid, split_commands, v1_valid
from .r1 import firmware_r1, port_r1
from .r2 import firmware_r2, legacy_rates, port_r2, v2_frame, v2_unframe, xor_checksum
from .r3 import (
    R3Result,
    R3Trial,
    analyse_stop,
    executed_before_hello,
    firmware_r3,
    r3_problems,
    stop_bound,
    travel_bound,
)
from .report import Results, markdown, problems, r3_table
from .runner import main, run

__all__ = [
    "CORRUPTIONS",
    "FULL",
    "MUTATIONS",
    "QUICK",
    "Legacy",
    "Lockstep",
    "R1Slice",
    "R2Result",
    "R3Result",
    "R3Trial",
    "Results",
    "analyse_stop",
    "corrupt",
    "executed_before_hello",
    "firmware_r1",
    "firmware_r2",
    "firmware_r3",
    "frame_valid",
    "legacy_rates",
    "line_valid",
    "main",
    "markdown",
    "mutate",
    "port_r1",
    "port_r2",
    "problems",
    "r1_lines",
    "r3_problems",
    "r3_table",
    "random_line",
    "run",
    "split_commands",
    "stop_bound",
    "travel_bound",
    "v1_valid",
    "v2_frame",
    "v2_unframe",
    "valid_line",
    "xor_checksum",
]
