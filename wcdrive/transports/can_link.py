"""The two ends of a chair on CAN.

``CanLink``: what ``wccan://<interface>/<channel>`` (and ``wcdrive.connect("can://...")``) opens; a
serial-like object (``write``/``read``/``in_waiting``/``close``) that turns the host's
protocol lines into command frames and the chair's frames back into the board's
lines, so ``Wheelchair`` works over CAN unchanged.

``CanGateway``: puts a chair (a serial port: a real Mega, ``wcsim://``, a pty) on a
bus: command frames become framed protocol lines to the board, and every line the
board sends becomes frames. ``wcdrive can-gateway`` runs one.

Both take any ``can.BusABC``: ``socketcan`` on a real bus, python-can's ``virtual``
interface in tests.
"""

from __future__ import annotations

import threading
import time

import can

from wcdrive.boards.receive_buffer import ReceiveBuffer
from wcdrive.errors import WcdriveConnectionError
from wcdrive.protocol.can_frames import (
    CHAIR_TO_HOST,
    CONTROL,
    CONTROL_OPS,
    HOST_TO_CHAIR,
    CanCodecError,
    TelemetryAssembler,
    command_to_frames,
    frame_to_command,
    message_to_frames,
)
from wcdrive.protocol.codec import LINE_COUNTER_WRAP, Boot, Hello, LineDecoder, board_frame, parse_line


def open_bus(interface: str, channel: str) -> can.BusABC:
    """python-can's bus, or ``WcdriveConnectionError`` saying how to bring it up."""
    try:
        return can.Bus(interface=interface, channel=channel)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise WcdriveConnectionError(
            f"cannot open CAN {interface}/{channel}: {exc} (for socketcan: "
            "sudo ip link set can0 up type can bitrate 500000)") from exc


class CanLink:
    """Host end: serial-like, over a bus. The lines it rebuilds from frames speak the
    board's protocol as the board would: plain until a ``HELLO:4`` (or later), protocol
    v4 frames from that line on, with a counter of its own, plain again from a ``BOOT:``
    line. The bus checked each CAN frame (its CRC-15), and the gateway the board's line
    it came from (protocol/CAN.md)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self._counter = 0
        self._framed = False
        self._lines = TelemetryAssembler()
        self._rx = ReceiveBuffer()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="wcdrive-can-link", daemon=True)
        self._thread.start()

    def start(self) -> CanLink:
        """The receiver runs from construction: for the interface of threaded boards."""
        return self

    @property
    def closed(self) -> bool:
        """True once ``close`` was called."""
        return self._stop.is_set()

    @property
    def rx_dropped(self) -> int:
        """Bytes received and dropped because nobody read them and the buffer was full."""
        return self._rx.dropped

    def reset_input(self) -> None:
        """Drops what was received and not yet read."""
        self._rx.clear()

    def write(self, data: bytes) -> int:
        """Each complete protocol line becomes its command frames (ValueError for a
        line that has no CAN form)."""
        for line in data.splitlines(keepends=True) or [data]:
            if not line.strip():
                continue
            try:
                frames = command_to_frames(line)
            except CanCodecError as exc:
                raise ValueError(str(exc)) from exc
            for can_id, payload in frames:
                self.bus.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
        return len(data)

    def flush(self) -> None:
        """Nothing to wait for: ``write`` puts the frames on the bus."""

    def read(self, size: int = 1, timeout: float | None = 0.1) -> bytes:
        """Up to ``size`` bytes of the board's lines; waits up to ``timeout`` s for the first."""
        return self._rx.read(size, timeout)

    @property
    def in_waiting(self) -> int:
        """Bytes of the board's lines received and not yet read."""
        return len(self._rx)

    def _receive(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None or msg.arbitration_id not in CHAIR_TO_HOST:
                continue
            text = self._lines.feed(msg.arbitration_id, bytes(msg.data))
            if not text:
                continue
            line = text.rstrip(b"\r\n")
            if line.startswith((b"BOOT:", b"HELLO:")):        # only these change the framing
                message = parse_line(line)
                if isinstance(message, Boot):
                    self._framed = False
                elif isinstance(message, Hello):
                    self._framed, self._counter = message.lines_framed, 0
            if self._framed:
                self._rx.put(board_frame(line, self._counter))
                self._counter = (self._counter + 1) % LINE_COUNTER_WRAP
            else:
                self._rx.put(text)

    def close(self) -> None:
        """Stops the receiver, wakes a blocked ``read`` and shuts the bus down."""
        self._stop.set()
        self._thread.join(timeout=2)
        self._rx.close()
        self.bus.shutdown()


def open_can_link(interface: str, channel: str) -> CanLink:
    """The host end on ``interface``/``channel`` (python-can's names)."""
    if not interface or not channel:
        raise ValueError("use wccan://<interface>/<channel>, e.g. wccan://socketcan/can0 or "
                         "wccan://virtual/chair")
    return CanLink(open_bus(interface, channel))


class CanGateway:
    """Chair end: a serial port (``read``/``write``) bridged onto ``bus``."""

    def __init__(self, bus: can.BusABC, port) -> None:
        self.bus = bus
        self.port = port
        self.dropped = 0            # frames or lines with no counterpart
        # the board's lines: frames only once it answered HELLO:4, plain from a BOOT: line
        # or a plain hello on
        self._decoder = LineDecoder()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._to_chair, name="can-gw-in", daemon=True),
                         threading.Thread(target=self._to_bus, name="can-gw-out", daemon=True)]

    def start(self) -> CanGateway:
        """Starts both directions; returns the gateway."""
        for t in self._threads:
            t.start()
        return self

    def _to_chair(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None or msg.arbitration_id not in HOST_TO_CHAIR:
                continue
            try:
                line = frame_to_command(msg.arbitration_id, bytes(msg.data))
            except (CanCodecError, ValueError):
                self.dropped += 1
                continue
            if msg.arbitration_id == CONTROL and CONTROL_OPS.get(msg.data[0]) == b"hello":
                self._decoder.framed = False        # a plain hello: the board answers v3
            self.port.write(line)

    def _to_bus(self) -> None:
        decoder = self._decoder
        while not self._stop.is_set():
            try:
                data = self.port.read(256)
            except Exception:
                if self._stop.is_set():
                    return
                time.sleep(0.05)
                continue
            for message in decoder.feed(data or b""):
                if isinstance(message, Hello):
                    decoder.framed = message.lines_framed   # v4: only frames from now on
                frames = message_to_frames(message)
                if not frames:
                    self.dropped += 1
                for can_id, payload in frames:
                    self.bus.send(can.Message(arbitration_id=can_id, data=payload,
                                              is_extended_id=False))

    def close(self) -> None:
        """Stops both directions and shuts the bus down (the gateway owns it)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        self.bus.shutdown()

    def __enter__(self) -> CanGateway:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
