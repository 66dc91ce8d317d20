"""One numbering for every host that frames its commands: ``Wheelchair`` (through
``RequestTracker``) and ``SteppedChair`` take each frame from the same core,
``wcdrive.protocol.exchange.Exchange``, and so send the same bytes for the same calls."""

from __future__ import annotations

import pytest

import wcdrive
from wcdrive.protocol.codec import MAX_ANGULAR, encode_cmdvel
from wcdrive.protocol.exchange import Exchange
from wcdrive.testing.stepped import SteppedChair

STOP = encode_cmdvel(0.0, 0.0)


class _Spy:
    """Every frame an ``Exchange`` hands out, in order."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.frames: list[bytes] = []
        real = Exchange.next_frame

        def next_frame(exchange: Exchange, body: bytes, *, motion: bool = False) -> tuple[int, bytes]:
            seq, data = real(exchange, body, motion=motion)
            self.frames.append(data)
            return seq, data

        monkeypatch.setattr(Exchange, "next_frame", next_frame)


class _WiredChair(SteppedChair):
    """A ``SteppedChair`` that keeps what it puts on the board's wire."""

    def __init__(self, *, neutral: bool = True) -> None:
        self.wire: list[bytes] = []                 # before: the constructor may send
        super().__init__(neutral=neutral)

    def send(self, data: bytes) -> None:
        self.wire.append(data)
        super().send(data)


def _lines(chunks: list[bytes]) -> list[bytes]:
    return b"".join(chunks).splitlines(keepends=True)


def test_wheelchair_and_stepped_chair_number_their_frames_through_one_exchange(
        monkeypatch: pytest.MonkeyPatch) -> None:
    spy = _Spy(monkeypatch)
    chair = wcdrive.connect("sim://", record=True)
    assert isinstance(chair, wcdrive.Wheelchair)
    with chair:
        chair.set_velocity(0.3, 0.0)
        chair.set_wheels(1.0, 2.0)                  # (left, right)
        chair.set_velocity(0.0, MAX_ANGULAR)        # at the limit: sent as the board reads it
        chair.stop()
        host = _lines([data for _, data in chair.recording.sent])
    from_host_core = spy.frames[:len(host)]

    spy.frames.clear()
    stepped = _WiredChair(neutral=False)            # its opening as connect()'s, below
    for _ in range(sum(b":hello:4*" in line for line in host)):   # the handshake's hellos
        stepped.command(b"hello:4")
    # connect()'s neutral commands (wait_for_neutral: one, and more until the board
    # confirms one); the program's own stop() is the last line
    for _ in range(sum(b":" + STOP + b"*" in line for line in host[:-1])):
        stepped.stop()
    stepped.set_velocity(0.3, 0.0)
    stepped.set_wheels(left=1.0, right=2.0)
    stepped.set_velocity(0.0, MAX_ANGULAR)
    stepped.stop()

    assert _lines(stepped.wire) == host             # the same bytes, the same numbers
    assert from_host_core == host                   # each of them from the exchange
    assert spy.frames == stepped.wire
    assert [line.split(b":")[0] for line in host[-4:]] == [b"$%d" % n for n in range(len(host) - 3,
                                                                                     len(host) + 1)]
