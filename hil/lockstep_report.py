"""What a lock-step comparison finds: a ``Report`` (what was compared, and the bytes
lost and accounted for) listing every ``Mismatch`` between the port and the firmware,
each at its event, with both values as text.

Both sides of a mismatch are text (a float as its bits and its repr, an integer in
hex, a stretch of TX bytes, a stall's gap), so that one record holds every kind of
difference and prints as it was found.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Mismatch", "Report"]


@dataclass
class Mismatch:
    """One difference: the event's index (-1: the state after ``setup()``), the ticks so
    far, the field and both values."""

    event_index: int
    tick: int
    field: str
    port: str
    firmware: str

    def __str__(self) -> str:
        return (f"event {self.event_index} (tick {self.tick}): {self.field} "
                f"port={self.port} firmware={self.firmware}")


@dataclass
class Report:
    """What ``compare`` found: events, ticks and values compared, the mismatches and the
    firmware's TX byte count; the received bytes lost unseen (``lost_bytes``, each also a
    mismatch), those lost and accounted for (``rx_lost``: a full ring or an overrun, seen
    by the firmware and the port alike; ``rx_off``: sent while the receiver was off,
    before ``Serial.begin`` or during a reset, or still in the ring at a reset), and the
    stalls of the control tick (each also a mismatch)."""

    events: int
    ticks: int
    fields_compared: int
    mismatches: list[Mismatch]
    tx_bytes: int
    lost_bytes: int = 0
    rx_lost: int = 0
    rx_off: int = 0
    stalls: int = 0
