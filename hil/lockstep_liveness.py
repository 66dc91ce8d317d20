"""The two checks of a lock-step ``Recording`` that no comparison of values can look
away from, each a list of ``Mismatch``: ``_delivery``, every byte the host sent reached
the firmware's parser or was lost where the firmware saw the loss; and ``_stalls``, the
firmware kept ticking. ``wcdrive.hil.lockstep_comparison.compare`` adds both to its
``Report``.

Every byte the host sent must reach the firmware's parser, or be lost where the
firmware saw the loss: the harness models the USART's two-frame FIFO and its data
overrun (``VirtualMega.rx_lost``), the firmware's RX interrupt counts a full ring and
an overrun (``rxLost``) and marks the place, and ``loop()`` hands the mark to ``rxGap``
(an event here, given to the port as it is: which bytes the chip loses is a matter of
its timing, which the port does not model; what the firmware does about it is). Bytes
lost unseen are mismatches (``lost_bytes``). And the firmware must keep ticking: a gap
between control ticks longer than the period plus ``TICK_TOLERANCE_MS``, or a
``millis()`` that does not follow the clock, is a mismatch (``stalls``). Both go boot
by boot (``_boots``): a reset ends one boot's ticks and bytes, and the next boot
starts again from ``setup()``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

from wcdrive.boards.simavr.virtual_mega import F_CPU
from wcdrive.firmware.constants import CONTROL_PERIOD_MS
from wcdrive.hil.lockstep_recording import Recording
from wcdrive.hil.lockstep_report import Mismatch

__all__ = ["MILLIS_TOLERANCE_MS", "TICK_TOLERANCE_MS"]

#: How late a control tick may be before the gap counts as a stall (ms past the period).
TICK_TOLERANCE_MS = 10
#: How far ``millis()`` may drift from the cycle clock between two ticks (ms).
MILLIS_TOLERANCE_MS = 2


def _boots(recording: Recording) -> list[tuple[int, int]]:
    """The cycle spans [start, end) of each boot of the run."""
    cuts = [c for c, _, _ in recording.resets]
    return list(zip([0, *cuts], [*cuts, recording.end_cycle], strict=True))


def _stalls(recording: Recording) -> list[Mismatch]:
    """The control tick must keep running, boot by boot: no gap between ticks (or from a
    boot to its first tick, or from the last tick to the end) longer than the period
    plus ``TICK_TOLERANCE_MS`` (a boot's first tick may also take setup()'s time, the
    period again), and ``millis()`` moving with the clock between ticks."""
    out: list[Mismatch] = []
    per_ms = F_CPU // 1000
    limit = (CONTROL_PERIOD_MS + TICK_TOLERANCE_MS) * per_ms
    ticks = [(i, ev) for i, ev in enumerate(recording.events) if ev.kind == "tick"]
    count = 0
    for start, end in _boots(recording):
        mine = [(i, ev) for i, ev in ticks if start <= ev.cycle < end]
        marks = [(-1, start), *((i, ev.cycle) for i, ev in mine), (-1, end)]
        for k, ((where, a), (_, b)) in enumerate(itertools.pairwise(marks)):
            allowed = limit * 2 if k == 0 else limit
            if b - a > allowed:
                out.append(Mismatch(where, count + k, "stall",
                                    f"a control tick every {CONTROL_PERIOD_MS} ms",
                                    f"none for {(b - a) / per_ms:.1f} ms (cycles {a}..{b})"))
        for (_, e0), (j, e1) in itertools.pairwise(mine):
            clock_ms = (e1.cycle - e0.cycle) / per_ms
            millis_ms = (e1.arg - e0.arg) & 0xFFFFFFFF
            if abs(millis_ms - clock_ms) > MILLIS_TOLERANCE_MS:
                out.append(Mismatch(j, count, "stall", f"millis() +{clock_ms:.1f} (the clock)",
                                    f"millis() +{millis_ms}"))
        count += len(mine)
    return out


@dataclass
class _Delivery:
    mismatches: list[Mismatch] = field(default_factory=list)
    lost_bytes: int = 0
    rx_lost: int = 0
    rx_off: int = 0


def _delivery(recording: Recording) -> _Delivery:
    """Every byte the host sent, boot by boot, against what reached ``processByte``: the
    firmware's bytes must be the host's less those lost, and each loss must be marked
    (an ``rxGap`` event before the next byte) and counted (``rxLost``); see the module
    docstring."""
    d = _Delivery()
    lost = {loss.index: loss for loss in recording.rx_lost}
    d.rx_off = sum(1 for loss in recording.rx_lost if loss.cause == "receiver_off")
    events = recording.events
    count_before = [recording.initial] + [booted for _, _, booted in recording.resets]
    for k, (start, end) in enumerate(_boots(recording)):
        # The host's bytes that reached the USART in this boot and were not lost there:
        # (index, byte, carries DOR: the first after a run of overrun losses).
        host: list[tuple[int, int, bool]] = []
        for index, (cycle, byte) in enumerate(recording.rx_wire):
            if start <= cycle < end and index not in lost:
                prev = lost.get(index - 1)
                host.append((index, byte, prev is not None and prev.cause == "overrun"))
        wire = bytes(b for _, b, _ in host)
        mine = [(i, ev) for i, ev in enumerate(events) if start <= ev.cycle < end and ev.kind != "tick"]
        # (first event, losses counted before it: rxGap's count, -1 none, bytes)
        segments: list[tuple[int, int, bytearray]] = []
        for i, ev in mine:
            if ev.kind == "gap":
                segments.append((i, ev.arg, bytearray()))
            elif not segments:
                segments.append((i, -1, bytearray([ev.arg])))
            else:
                segments[-1][2].append(ev.arg)
        p = ring_drops = 0
        dor_read = 0
        for i, counted_here, data in segments:
            gap = counted_here >= 0
            if not data:
                continue
            # rxGap's count says how many bytes the ring dropped here (less one if the
            # next byte carries an overrun); 255 is a saturated count: search instead.
            at = -1
            if 0 <= counted_here < 255:
                for dor in (1, 0):
                    k = p + counted_here - dor
                    if p <= k < len(host) and host[k][2] == bool(dor) and wire.startswith(bytes(data), k):
                        at = k
                        break
            if at < 0:
                at = wire.find(bytes(data), p)
            if at < 0:
                d.mismatches.append(Mismatch(i, 0, "RX", "the host's bytes", f"{bytes(data)[:40]!r} "
                                             f"(boot {k}): not what was sent"))
                d.lost_bytes += len(data)
                break
            skipped = at - p
            dor_first = host[at][2]
            dor_inside = [host[j][0] for j in range(at + 1, at + len(data)) if host[j][2]]
            if not gap and (skipped or dor_first):
                d.mismatches.append(Mismatch(i, 0, "RX", "a gap mark (rxGap)",
                                             f"{skipped or 'overrun'} bytes lost unseen before "
                                             f"byte {host[at][0]} (boot {k})"))
                d.lost_bytes += max(skipped, 1)
            elif gap and not skipped and not dor_first:
                d.mismatches.append(Mismatch(i, 0, "RX", "no loss", f"a gap mark before byte "
                                             f"{host[at][0]} (boot {k})"))
            if dor_inside:
                d.mismatches.append(Mismatch(i, 0, "RX", "a gap mark (rxGap)",
                                             f"overrun unseen before byte {dor_inside[0]} (boot {k})"))
                d.lost_bytes += len(dor_inside)
            ring_drops += skipped
            dor_read += int(dor_first) + len(dor_inside)
            p = at + len(data)
        # What the firmware counted: every ring drop and overrun before the last byte it
        # read, and perhaps some of the bytes after it (still in the ring or USART, or
        # dropped); the bytes still in flight at a reset are lost with the reset.
        in_boot = [ev for ev in events if start <= ev.cycle < end]
        final = in_boot[-1].after if in_boot and in_boot[-1].after else count_before[k]
        counted = int(final.get("rxLost", 0))
        trailing = len(host) - p
        expected = ring_drops + dor_read
        if not expected <= counted <= expected + trailing + sum(1 for _, _, dor in host[p:] if dor):
            d.mismatches.append(Mismatch(len(events), 0, "rxLost", f"{expected} (+ up to {trailing})",
                                         f"{counted} (boot {k})"))
        d.rx_lost += counted
        if k < len(recording.resets):
            d.rx_off += max(0, trailing - max(0, counted - expected))
    return d
