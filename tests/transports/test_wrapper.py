"""``PortWrapper``: every ``Port`` method reaches the wrapped port, each hook is called
where its contract says, and ``RecordingPort`` and the ROS tap log through them."""

from __future__ import annotations

import pytest
import serial

from tests.transports.fakeport import FakePort
from wcdrive.transports.port import Port
from wcdrive.transports.recording import RecordingPort
from wcdrive.transports.wrapper import PortWrapper


class Hooks(PortWrapper):
    """Upper-cases what the host writes, reverses what it reads, logs the calls."""

    def __init__(self, port: FakePort) -> None:
        super().__init__(port)
        self.calls: list[tuple[str, bytes]] = []

    def on_write(self, data: bytes) -> bytes:
        self.calls.append(("write", data))
        return data.upper()

    def on_sent(self, data: bytes) -> None:
        self.calls.append(("sent", data))

    def on_read(self, data: bytes) -> bytes:
        self.calls.append(("read", data))
        return data[::-1]

    def on_close(self) -> None:
        self.calls.append(("close", b""))


def test_a_wrapper_is_a_port_that_delegates_everything() -> None:
    inner = FakePort(timeout=0.3)
    port = PortWrapper(inner)
    assert isinstance(port, Port)
    assert port.timeout == 0.3
    port.timeout = 0.7
    assert inner.timeout == 0.7
    inner.feed(b"abc")
    assert port.in_waiting == 3
    assert port.read(2) == b"ab" and inner.reads == [2]
    assert port.write(b"x:1,") == 4 and inner.written == [b"x:1,"]
    port.flush()
    assert inner.flushed == 1
    port.reset_input_buffer()                       # FakePort has none: a no-op
    assert port.is_open and port.simulation is None
    with pytest.warns(DeprecationWarning, match=r"\.simulation"):
        assert port.board is None
    port.close()
    assert not inner.is_open and not port.is_open
    with pytest.raises(serial.SerialException):
        port.read(1)


def test_the_hooks_see_and_change_what_goes_through() -> None:
    inner = FakePort()
    port = Hooks(inner)
    assert port.write(b"abc") == 3                  # the caller's length
    assert inner.written == [b"ABC"]
    inner.feed(b"xyz")
    assert port.read(3) == b"zyx"
    assert port.read(3) == b""                      # on_read sees an empty read too
    port.close()
    assert port.calls == [("write", b"abc"), ("sent", b"ABC"), ("read", b"xyz"), ("read", b""),
                          ("close", b"")]


def test_an_empty_on_write_writes_nothing() -> None:
    inner = FakePort()
    port = Hooks(inner)
    port.on_write = lambda data: b""                # type: ignore[method-assign]
    assert port.write(b"lost") == 4
    assert inner.written == [] and port.calls == []


def test_a_write_that_fails_is_not_reported_sent() -> None:
    inner = FakePort()
    port = Hooks(inner)
    inner.close()
    with pytest.raises(serial.SerialException):
        port.write(b"abc")
    assert port.calls == [("write", b"abc")]


def test_recording_port_logs_through_the_hooks() -> None:
    inner = FakePort()
    port = RecordingPort(inner)
    port.write(b"hello\n")
    inner.feed(b"HELLO:3\r\n")
    assert port.read(100) == b"HELLO:3\r\n"
    assert port.read(100) == b""
    assert port.recording.sent_bytes == b"hello\n"
    assert port.recording.received_bytes == b"HELLO:3\r\n"
    assert len(port.recording.received) == 1         # an empty read is not logged
    port.close()
    assert port.recording.sent_bytes == b"hello\n"   # the recording stays


def test_the_ros_tap_publishes_through_the_hooks() -> None:
    from wcdrive.ros2.bridge import TapPort

    class Publisher:
        def __init__(self) -> None:
            self.sent: list[bytes] = []
            self.got: list[bytes] = []

        def wrote(self, data: bytes) -> None:
            self.sent.append(data)

        def read(self, data: bytes) -> None:
            self.got.append(data)

    publisher = Publisher()
    inner = FakePort()
    tap = TapPort(RecordingPort(inner), publisher)  # type: ignore[arg-type]
    tap.write(b"x:0.5,t:0,\n")
    inner.feed(b"ENC:1,2\r\n")
    assert tap.read(64) == b"ENC:1,2\r\n"
    assert tap.read(64) == b""
    assert publisher.sent == [b"x:0.5,t:0,\n"] and publisher.got == [b"ENC:1,2\r\n"]
    assert tap.recording.sent_bytes == b"x:0.5,t:0,\n"   # the wrapped RecordingPort's


def test_the_recording_is_found_through_any_wrappers() -> None:
    """``recording_of``: a ``RecordingPort``'s own, or one behind wrappers (a ROS tap, an
    injected fault) however deep; None without a ``RecordingPort`` in the chain."""
    from wcdrive.ros2.bridge import TapPort
    from wcdrive.transports.faulty import FaultyPort
    from wcdrive.transports.recording import recording_of

    recorded = RecordingPort(FakePort())
    tap = TapPort(FaultyPort(recorded), object())       # type: ignore[arg-type]
    assert recording_of(recorded) is recorded.recording
    assert recording_of(tap) is recorded.recording and tap.recording is recorded.recording
    assert recording_of(FakePort()) is None and recording_of(PortWrapper(FakePort())) is None
    assert TapPort(FakePort(), object()).recording is None    # type: ignore[arg-type]


def test_the_optional_pyserial_members_are_typed_capabilities() -> None:
    """``is_open``, ``reset_input_buffer`` and ``cancel_read`` are optional on a Port:
    pyserial's ports have them (``loop://``: the first two), a bare Port need not. A
    wrapper asks its port's through the capability protocols: it drops the bytes of a
    port that can, takes a port without ``is_open`` as open, and its own members say
    what the port behind it has."""
    from wcdrive.transports.port import CancellablePort, OpenStatePort, ResettablePort

    loop = serial.serial_for_url("loop://", timeout=0.1)
    assert isinstance(loop, OpenStatePort) and isinstance(loop, ResettablePort)
    loop.write(b"stale")
    loop.flush()
    wrapped = PortWrapper(loop)
    assert isinstance(wrapped, ResettablePort)
    wrapped.reset_input_buffer()
    assert loop.in_waiting == 0
    wrapped.close()

    class Bare:
        """The five members of ``Port`` and nothing more."""

        timeout: float | None = 0.0

        @property
        def in_waiting(self) -> int:
            return 0

        def read(self, size: int = 1) -> bytes:
            return b""

        def write(self, data: bytes) -> int | None:
            return len(data)

        def flush(self) -> None:
            pass

        def close(self) -> None:
            pass

    bare = Bare()
    assert isinstance(bare, Port)
    assert not isinstance(bare, (OpenStatePort, ResettablePort, CancellablePort))
    around = PortWrapper(bare)
    assert around.is_open
    around.reset_input_buffer()                     # a no-op
