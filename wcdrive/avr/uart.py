"""The Mega's serial port (USART0) as the firmware and the simulator see it."""

from __future__ import annotations

#: Cycles per received byte. 115200 baud with U2X is 117,647 baud: 10 bits a byte on a
#: real wire; simavr 1.6 takes 11 bit times, and both backends use this figure so that
#: a command completes at the same cycle on each.
UART_BYTE_CYCLES = 1496
