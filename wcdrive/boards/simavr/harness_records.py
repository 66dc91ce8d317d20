"""What the harness records as the firmware runs, as Python values: ``Reset`` (one
reset of the AVR), ``Hit`` (one entry of a hooked function) and ``RxLoss`` (one byte
the USART0 receiver lost), with the codes the harness gives them in
(``RESET_CAUSES``, ``RX_LOSS_CAUSES``) and the MCUSR flags a reset leaves.

The codes are positions: ``RESET_CAUSES[i]`` is wcsim.c's ``WCSIM_RESET_*`` number
``i`` and ``RX_LOSS_CAUSES[i]`` its receiver's loss cause ``i``, so each tuple changes
with the C enum it decodes. The records are frozen: a log of what happened is never
edited afterwards.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Reset causes by the harness's code (wcsim.c, ``WCSIM_RESET_*``).
RESET_CAUSES = ("power_on", "external", "brownout", "watchdog")
#: MCUSR's flags (ATmega2560 datasheet, 11.5.1).
PORF, EXTRF, BORF, WDRF, JTRF = 0x01, 0x02, 0x04, 0x08, 0x10


#: Why the USART0 receiver lost a byte (wcsim.c, ``wcsim_rx_lost_t``).
RX_LOSS_CAUSES = ("overrun", "receiver_off")


@dataclass(frozen=True)
class RxLoss:
    """A byte the USART0 receiver lost (the harness models its two-frame FIFO and shift
    register, and data overrun): the cycle, its index among the bytes sent to the board
    (0 the first since power-on), the byte, and why (``RX_LOSS_CAUSES``)."""

    cycle: int
    index: int
    byte: int
    cause: str


@dataclass(frozen=True)
class Reset:
    """One reset of the AVR: the cycle it happened at, its cause (one of
    ``RESET_CAUSES``) and MCUSR right after it (what the firmware finds at boot)."""

    cycle: int
    cause: str
    mcusr: int


@dataclass(frozen=True)
class Hit:
    """One logged function entry: the cycle, the function, its first 32-bit argument."""

    cycle: int
    function: str
    arg: int
