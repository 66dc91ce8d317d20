"""``wcdrive.connect(url) -> Wheelchair``: what navigation code imports.

    import wcdrive
    with wcdrive.connect("sim://") as chair:            # the simulated chair (default)
        for _ in range(50):
            chair.set_velocity(0.5, 0.1)                # m/s, rad/s; send at >= 2 Hz
            time.sleep(0.1)
        print(chair.odometry.pose)
    # leaving the block stops the chair and closes the link

URLs map onto pyserial (the query goes to the handler, which alone parses it):

- ``sim://[?speed=S&seed=N&chair=chair.toml]`` -> ``wcsim://``: in process, the bit-exact
  port + pymunk plant, at real time (``speed=S``: S times real time);
- ``simavr://[path/to.elf][?realtime=0&speed=S&chair=chair.toml]`` -> ``wcavr://``: the
  compiled firmware in simavr driving the pymunk chair, at real time by default like a
  real board (``speed=S``: S times real time; ``realtime=0``: as fast as simavr runs);
- on both, ``chair=chair.toml`` gives the plant the ``[chair]`` table of that file in
  place of the default figures (``wcdrive.plant.params.load_chair``; ``wcdrive bench
  identify`` fits one to recordings of a real chair, docs/bench.md);
- on both, ``world=W`` puts the chair among walls it collides with (a map_server YAML,
  a hand-written world's TOML, or a bundled world: hospital_corridor, furnished_room),
  ``start=x,y,heading_deg`` its pose there, and ``lidar=rplidar_s3`` an RPLidar S3 on it
  (the seed's mount): ``chair.scan()`` and ``chair.on_scan(cb)`` give its scans;
- ``can://<interface>/<channel>`` -> ``wccan://``: a chair behind a ``wcdrive can-gateway``;
- any ``scheme://`` pyserial opens (``wcsim://``, ``socket://``, ``rfc2217://``);
- a device path such as ``/dev/ttyACM0``: opened exclusively (a second program gets
  ``WcdriveBusyError``), reopened after an unplug;
- a robot plugin's URL (``wcdrive.host.robots``): ``eddie+sim://[?speed=S&seed=N]`` ->
  ``wceddie://``, a simulated Parallax Eddie, and ``eddie:///dev/ttyUSB0``, a real one,
  both an ``EddieRobot`` (docs/eddie.md) with the navigation surface of
  ``wcdrive.host.robot.Robot``.

On connect the board resets (a real Mega does when its port opens); the API waits
for it to boot, then says ``hello:4`` (a v3 frame, tried 3 times with growing waits).
A protocol-v4 board answers ``HELLO:4,final_control,<version>,<build id>,<profile>``; from then on
every line the host writes is a frame with a CRC-16 and a sequence number (a corrupted
byte is rejected, never driven; the board refuses unframed lines but stops), every
line the board sends ends in a line counter and a CRC-16 (one that fails is dropped
and counted in ``chair.link_stats``, never believed),
``estop()``/``reset_estop()`` and ``get_param()``/``set_param()`` are acknowledged,
retried requests, and telemetry carries the ``TLM:`` fields. A board that never
answers hello raises ``WcdriveProtocolError``, as does one that answers with another
version.

``legacy=True`` drives a board that never answers hello (the seed's firmware) with
protocol v1 instead: bare ``x:0.500,t:0.100,`` lines. Lost then: the CRC (a corrupted
byte can change a speed), every answer (a refused command goes unnoticed), the latched
e-stop (``estop()`` sends a stop and raises), the parameters, the ``TLM:`` telemetry
(``status``, the watchdog and e-stop flags) and the firmware's identity. The liveness
check still works on the feedback lines.

The firmware stops the chair when no valid command arrives for 500 ms: hold a
velocity by sending it again at 2 Hz or faster (as a ROS ``cmd_vel`` stream does).
The host watches the board in turn: no line for ``link_timeout`` s (default 0.15 s,
three feedback periods; on ``sim://`` and ``simavr://`` seconds of the board's own
clock, so that a board run faster than real time, or left behind the wall clock by a
loaded machine, is not taken for a silent one) and ``chair.link_ok`` turns False, ``chair.on_link``
callbacks get a ``LinkLost``, and motion calls raise ``WcdriveConnectionError``; lines
flowing again restore it (``LinkRestored``). A device path that disappears (unplugged)
is reopened until ``reconnect_timeout``, and the new board is greeted again.

Every failure of ``connect`` is a ``WcdriveError`` that names the URL or device:
``WcdriveConnectionError`` (bad URL, no such device), ``WcdriveBusyError`` (another
program has the device), ``WcdrivePermissionError``, ``WcdriveProtocolError`` (no
hello, unknown version), ``WcdriveTimeoutError`` (no feedback: no firmware, wrong baud
rate).
"""

from __future__ import annotations

import errno
from collections.abc import Callable
from typing import Any

import serial

from wcdrive.errors import (
    WcdriveBusyError,
    WcdriveConnectionError,
    WcdrivePermissionError,
)
from wcdrive.host.robot import Robot
from wcdrive.host.robots import Link, entry_for
from wcdrive.host.scan_feed import ScanSource
from wcdrive.host.wheelchair import (
    LINK_TIMEOUT,
    LinkEvent,
    LinkLost,
    LinkRestored,
    Reset,
    Telemetry,
    Wheelchair,
)
from wcdrive.transports.port import Port, simulation_of
from wcdrive.transports.recording import RecordingPort, recording_of

__all__ = ["SCHEMES", "LinkEvent", "LinkLost", "LinkRestored", "Reset", "Telemetry", "Wheelchair", "connect"]

#: wcdrive's short URL schemes and the pyserial scheme each one is.
SCHEMES = {"sim": "wcsim", "simavr": "wcavr", "can": "wccan"}
#: How long a read waits: the session's reader thread polls at this period.
READ_TIMEOUT = 0.1


def _errno(exc: BaseException) -> int | None:
    """The OS error number behind a pyserial exception (its own, or its cause's)."""
    seen: BaseException | None = exc
    while seen is not None:
        number = getattr(seen, "errno", None)
        if isinstance(number, int):
            return number
        seen = seen.__cause__ or seen.__context__
    return None


def _open_device(path: str) -> serial.Serial:
    try:
        return serial.Serial(path, 115200, timeout=READ_TIMEOUT, exclusive=True)
    except (serial.SerialException, OSError) as exc:
        number, text = _errno(exc), str(exc)
        if number in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
            raise WcdrivePermissionError(
                f"permission denied on {path}: add yourself to the dialout group "
                "(sudo usermod -aG dialout $USER, then log in again)") from exc
        if number == errno.ENOENT or "No such file" in text:
            raise WcdriveConnectionError(
                f"cannot open {path}: no such device; is the board plugged in? "
                "(ls /dev/ttyACM* /dev/ttyUSB*)") from exc
        if number in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text:
            raise WcdriveBusyError(
                f"cannot open {path}: it is busy, another program has it open (a terminal, "
                "another wcdrive, ModemManager?): close that first (fuser -v " + path + ")") from exc
        raise WcdriveConnectionError(f"cannot open {path}: {exc}") from exc


def _open_url(url: str) -> Port:
    scheme, sep, rest = url.partition("://")
    target = f"{SCHEMES.get(scheme, scheme)}://{rest}" if sep else url
    try:
        port: Port = serial.serial_for_url(target, timeout=READ_TIMEOUT)
    except Exception as exc:                    # whatever the handler raises: name the URL
        shown = url if target == url else f"{url} ({target})"
        raise WcdriveConnectionError(f"cannot open {shown}: {exc}") from exc
    return port


def _board_clock(port: Port) -> Callable[[], float | None] | None:
    """A simulated board's own clock (``Simulated.reported_time``: how far its output
    has come), for the link monitor; None for a device, a pty or a CAN link."""
    sim = simulation_of(port)
    if sim is None:
        return None
    return lambda: sim.reported_time


def _scan_source(port: Port) -> ScanSource | None:
    """A simulated board's lidar (``BoardLidar``), for ``Wheelchair.scan``; None for a
    board without one, a device, a pty or a CAN link."""
    sim = simulation_of(port)
    return sim.lidar if sim is not None else None


def connect(url: str = "sim://", *, boot_timeout: float = 10.0, record: bool | str = False,
            legacy: bool = False, link_timeout: float | None = None, ros: Any = None,
            **options: Any) -> Wheelchair | Robot:
    """Opens ``url``, waits for the board's boot and feedback, says hello, and sends a
    neutral command the board confirms (``wcdrive.host.neutral``; module
    docstring). ``record``: keep every byte both ways (``chair.recording``) for
    ``wcdrive.tools.replay``; ``record="run.mcap"``: write ROS 2 messages (odometry, tf, the
    wheels, the commands, the board's lines; on a simulated board its ground truth and
    gyro too) into that MCAP file, finished when the chair closes
    (``wcdrive.ros2.bridge.ChairPublisher``). ``ros``: publish those messages to this sink
    instead (a ``wcdrive.ros2.bridge.McapSink`` or ``LiveSink``; closed with the chair), with
    ``record=True`` too if wanted. ``legacy``: drive a board that never answers hello with
    protocol v1 instead of raising ``WcdriveProtocolError``. ``link_timeout``: seconds
    without a line before the link counts as lost (default 0.15 s, counted on a
    simulated board's own clock). ``options`` go to ``Wheelchair``
    (``odometry_method``, ``reconnect_timeout``, ``stop_on_signals``)."""
    publisher = None
    if isinstance(record, str) or ros is not None:
        from wcdrive.protocol.spec import real
        from wcdrive.ros2 import bridge as ros2

        sink = ros if ros is not None else ros2.McapSink(str(record))
        record = record is True
        publisher = ros2.ChairPublisher(sink, real("WHEEL_RADIUS"), real("WHEELBASE"), round(real("CPR")))
        user_close = options.pop("on_close", None)

        def close_sink() -> None:
            try:
                if user_close is not None:
                    user_close()
            finally:
                publisher.sink.close()

        options["on_close"] = close_sink

    def wrap(port: Port) -> Port:
        if publisher is not None:
            from wcdrive.ros2.bridge import TapPort

            return TapPort(RecordingPort(port) if record else port, publisher)
        return RecordingPort(port) if record else port

    plugin = entry_for(url)
    if plugin is not None:
        return plugin.connect(url, Link(_open_url, _open_device, wrap), boot_timeout=boot_timeout,
                              **options)

    if "://" in url:
        port = _open_url(url)
    elif url.startswith("/"):
        port = _open_device(url)
    else:
        raise WcdriveConnectionError(
            f"unsupported URL {url!r}: use sim://, simavr://[elf], can://<interface>/<channel>, "
            "another pyserial URL, or a device path")
    first = wrap(port)
    options.setdefault("name", url)
    if url.startswith("/"):
        def reopen() -> Port:
            again = _open_device(url)
            recording = recording_of(first)
            again_port = RecordingPort(again, recording) if recording is not None else again
            if publisher is not None:
                from wcdrive.ros2.bridge import TapPort

                return TapPort(again_port, publisher)
            return again_port

        options.setdefault("reopen", reopen)
    chair = Wheelchair(first, legacy=legacy,
                       link_timeout=LINK_TIMEOUT if link_timeout is None else link_timeout,
                       board_clock=_board_clock(port), scan_source=_scan_source(port), **options)
    if publisher is not None:
        publisher.attach(chair, simulation_of(port))
    try:
        chair.wait_for_telemetry(boot_timeout)   # the Mega resets on open: wait for it
        chair.wait_for_handshake(boot_timeout)
        chair.wait_for_neutral(boot_timeout)     # booted: it drives after a neutral command
    except BaseException:
        chair.close()
        raise
    return chair
