"""``wcdrive.connect(url) -> Wheelchair``: what navigation code imports.

    import wcdrive
    with wcdrive.connect("sim://") as chair:            # the simulated chair (default)
        for _ in range(50):
            chair.set_velocity(0.5, 0.1)                # m/s, rad/s; send at >= 2 Hz
            time.sleep(0.1)
        print(chair.odometry.pose)
    # leaving the block stops the chair and closes the link

URLs map onto pyserial (the query goes to the handler, which alone parses it):

- ``sim://[?speed=S&seed=N]`` -> ``wcsim://``: in process, the bit-exact port + pymunk plant;
- ``simavr://[path/to.elf][?realtime=1]`` -> ``wcavr://``: the compiled firmware in
  simavr driving the pymunk chair, as fast as it can unless ``realtime=1``;
- ``can://<interface>/<channel>`` -> ``wccan://``: a chair behind a ``wcdrive can-gateway``;
- any ``scheme://`` pyserial opens (``wcsim://``, ``socket://``, ``rfc2217://``);
- a device path such as ``/dev/ttyACM0``: reopened after an unplug.

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

from typing import Any

import serial

from wcdrive.errors import WcdriveConnectionError, WcdrivePermissionError, WcdriveTimeoutError
from wcdrive.transports.port import Port
from wcdrive.transports.recording import RecordingPort
from wcdrive.wheelchair import Telemetry, Wheelchair

__all__ = ["SCHEMES", "Telemetry", "Wheelchair", "connect"]

#: wcdrive's short URL schemes and the pyserial scheme each one is.
SCHEMES = {"sim": "wcsim", "simavr": "wcavr", "can": "wccan"}
#: How long a read waits: the session's reader thread polls at this period.
READ_TIMEOUT = 0.1


def _open_device(path: str) -> serial.Serial:
    try:
        return serial.Serial(path, 115200, timeout=READ_TIMEOUT)
    except serial.SerialException as exc:
        if isinstance(exc.__context__, PermissionError) or "Permission denied" in str(exc):
            raise WcdrivePermissionError(
                f"permission denied on {path}: add yourself to the dialout group "
                "(sudo usermod -aG dialout $USER, then log in again)") from exc
        raise WcdriveConnectionError(f"cannot open {path}: {exc}") from exc


def _open_url(url: str) -> Port:
    scheme, sep, rest = url.partition("://")
    if sep:
        url = f"{SCHEMES.get(scheme, scheme)}://{rest}"
    try:
        port: Port = serial.serial_for_url(url, timeout=READ_TIMEOUT)
    except (serial.SerialException, ValueError, OSError) as exc:
        raise WcdriveConnectionError(f"cannot open {url}: {exc}") from exc
    return port


def connect(url: str = "sim://", *, boot_timeout: float = 10.0, record: bool = False,
            **options: Any) -> Wheelchair:
    """Opens ``url``, waits for the board's boot and feedback, says hello. ``record``:
    keep every byte both ways (``chair.recording``) for ``wcdrive.replay``.
    ``options`` go to ``Wheelchair`` (``odometry_method``, ``reconnect_timeout``)."""
    def wrap(port: Port) -> Port:
        return RecordingPort(port) if record else port

    if "://" in url:
        chair = Wheelchair(wrap(_open_url(url)), **options)
    elif url.startswith("/"):
        chair = Wheelchair(wrap(_open_device(url)), reopen=lambda: _open_device(url), **options)
    else:
        raise WcdriveConnectionError(
            f"unsupported URL {url!r}: use sim://, simavr://[elf], can://<interface>/<channel>, "
            "another pyserial URL, or a device path")
    try:
        chair.wait_for_telemetry(boot_timeout)   # the Mega resets on open: wait for it
        chair.wait_for_handshake(boot_timeout)
    except WcdriveTimeoutError:
        chair.close()
        raise
    return chair
