"""Recordings of a serial session: every byte the host wrote and every byte the board
sent, with host timestamps, from the board's boot on. ``wcdrive.tools.replay`` runs one
through the Python port; ``wcdrive bench run --record`` makes them on a real board.

    chair = wcdrive.connect("/dev/ttyACM0", record=True)
    ...
    chair.recording.save("run.wcrec.json")

The file is JSON: ``{"meta": {...}, "sent": [[t, "hex"], ...], "received": [...]}``.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from wcdrive.transports.port import Port
from wcdrive.transports.wrapper import PortWrapper

FORMAT = "wcdrive-recording/1"


@dataclass
class Recording:
    """What the host wrote (``sent``) and read (``received``): (time, bytes) chunks."""

    sent: list[tuple[float, bytes]] = field(default_factory=list)
    received: list[tuple[float, bytes]] = field(default_factory=list)
    meta: dict[str, object] = field(default_factory=dict)

    @property
    def sent_bytes(self) -> bytes:
        """Every byte the host wrote, in order."""
        return b"".join(data for _, data in self.sent)

    @property
    def received_bytes(self) -> bytes:
        """Every byte the host read, in order."""
        return b"".join(data for _, data in self.received)

    def save(self, path: str | Path) -> Path:
        """Writes the JSON file; returns its path."""
        path = Path(path)
        path.write_text(json.dumps({
            "format": FORMAT, "meta": self.meta,
            "sent": [[t, d.hex()] for t, d in self.sent],
            "received": [[t, d.hex()] for t, d in self.received],
        }))
        return path

    @classmethod
    def load(cls, path: str | Path) -> Recording:
        """Reads a file written by ``save``."""
        data = json.loads(Path(path).read_text())
        if data.get("format") != FORMAT:
            raise ValueError(f"{path} is not a {FORMAT} file")
        return cls([(t, bytes.fromhex(h)) for t, h in data["sent"]],
                   [(t, bytes.fromhex(h)) for t, h in data["received"]], data.get("meta", {}))


class RecordingPort(PortWrapper):
    """Wraps a ``Port``; logs what goes through it into ``recording``: a write once the
    wrapped port took it, a read when it brought bytes. It is a ``Port`` itself
    (``PortWrapper``: ``timeout`` and the rest are the wrapped port's); closing it
    keeps the recording."""

    def __init__(self, port: Port, recording: Recording | None = None) -> None:
        super().__init__(port)
        self.recording = recording if recording is not None else Recording()
        self._lock = threading.Lock()

    def on_sent(self, data: bytes) -> None:
        """Logs ``data`` as sent."""
        with self._lock:
            self.recording.sent.append((time.monotonic(), data))

    def on_read(self, data: bytes) -> bytes:
        """Logs ``data`` as received (when there is any) and passes it on."""
        if data:
            with self._lock:
                self.recording.received.append((time.monotonic(), bytes(data)))
        return data


def recording_of(port: object) -> Recording | None:
    """The recording of ``port``: a ``RecordingPort``'s, or that of the port a
    ``PortWrapper`` (a ROS tap, an injected fault) wraps, however deep; None when no
    ``RecordingPort`` is in the chain."""
    while isinstance(port, PortWrapper):
        if isinstance(port, RecordingPort):
            return port.recording
        port = port.port
    return None
