"""``wcdrive.connect(url) -> Wheelchair``: what navigation code imports.

    import wcdrive
    with wcdrive.connect("sim://") as chair:            # the simulated chair (default)
        for _ in range(50):
            chair.set_velocity(0.5, 0.1)                # m/s, rad/s; send at >= 2 Hz
            time.sleep(0.1)
        print(chair.odometry.pose)
    # leaving the block stops the chair and closes the link

URLs: ``sim://[?speed=S&seed=N]`` (in process: the bit-exact port + pymunk plant),
``simavr://[path/to.elf][?realtime=1]`` (the compiled firmware in simavr driving the
pymunk chair, through a pty, so the real-port code path runs; as fast as it can
unless ``realtime=1``), a device path such as ``/dev/ttyACM0``, and
``can://<interface>/<channel>`` (a chair behind a ``wcdrive can-gateway``).

On connect the board resets (a real Mega does when its port opens); the API waits
for it to boot, then says hello. A protocol-v2 board answers, and from then on
motion commands go out as checksummed lines (a corrupted byte is rejected, never
driven), ``estop()``/``reset_estop()`` and ``get_param()``/``set_param()`` work with
acknowledged, retried requests, and telemetry carries the ``TLM:`` fields.

The firmware stops the chair when no valid command arrives for 500 ms: hold a
velocity by sending it again at 2 Hz or faster (as a ROS ``cmd_vel`` stream does).
A device path that disappears (unplugged) is reopened until ``reconnect_timeout``;
meanwhile commands raise ``WcdriveConnectionError``.
"""

from __future__ import annotations

import urllib.parse

import serial

from wcdrive.errors import WcdriveConnectionError, WcdrivePermissionError, WcdriveTimeoutError
from wcdrive.wheelchair import Telemetry, Wheelchair

__all__ = ["Telemetry", "Wheelchair", "connect"]


def _open_serial(path: str) -> serial.Serial:
    try:
        port = serial.Serial(path, 115200, timeout=0.1)
    except serial.SerialException as exc:
        if isinstance(exc.__context__, PermissionError) or "Permission denied" in str(exc):
            raise WcdrivePermissionError(
                f"permission denied on {path}: add yourself to the dialout group "
                "(sudo usermod -aG dialout $USER, then log in again)") from exc
        raise WcdriveConnectionError(f"cannot open {path}: {exc}") from exc
    return port


def connect(url: str = "sim://", *, boot_timeout: float = 10.0, record: bool = False,
            **options) -> Wheelchair:
    """Opens ``url``, waits for the board's boot and feedback, says hello. ``record``:
    keep every byte both ways (``chair.recording``) for ``wcdrive.replay``."""
    parts = urllib.parse.urlsplit(url)

    def wrap(port):
        if not record:
            return port
        from wcdrive.recording import RecordingPort

        return RecordingPort(port)

    if parts.scheme == "sim":
        port = serial.serial_for_url("wcsim://" + (f"?{parts.query}" if parts.query else ""), timeout=0.1)
        chair = Wheelchair(wrap(port), **options)
    elif parts.scheme == "simavr":
        from hil.pty_board import PtyBoard

        elf = (parts.netloc + parts.path) or None
        query = urllib.parse.parse_qs(parts.query)
        realtime = query.get("realtime", ["0"])[0] in ("1", "true", "yes")
        board = PtyBoard(elf, realtime=realtime).start(run_board=False)
        port = wrap(_open_serial(board.path))
        board.run_board()                  # like a Mega that resets when its port opens
        chair = Wheelchair(port, on_close=board.stop, **options)
    elif parts.scheme == "can":
        from wcdrive.can.link import open_can_link

        chair = Wheelchair(wrap(open_can_link(parts.netloc, parts.path.lstrip("/"))), **options)
    elif parts.scheme == "" and url.startswith("/"):
        chair = Wheelchair(wrap(_open_serial(url)), reopen=lambda: _open_serial(url), **options)
    else:
        raise ValueError(f"unsupported URL {url!r}: use sim://, simavr://[elf], "
                         "can://<interface>/<channel> or a device path")
    try:
        chair.wait_for_telemetry(boot_timeout)   # the Mega resets on open: wait for it
        chair.wait_for_handshake(boot_timeout)
    except WcdriveTimeoutError:
        chair.close()
        raise
    return chair
