"""ROS 2's command-line arguments as rcl reads them (``rcl_parse_arguments`` in rcl 9.2's
``rcl/src/rcl/arguments.c``, ROS 2 Jazzy): what ``wcdrive ros2 … --ros-args …`` takes.
Pure but for reading the ``--params-file`` files it is given.

``--ros-args`` opens a block of ROS arguments and ``--`` closes it (a second
``--ros-args`` inside is ignored; several blocks may follow each other). Inside:

- ``-r``/``--remap RULE``: a remap rule (``wcdrive.ros2.names.parse_remap``: topics,
  ``__node:=``, ``__ns:=``, a ``node:`` prefix for one node);
- ``-p``/``--param [node:]name:=VALUE``: a parameter, the value read as YAML
  (``wcdrive.ros2.params``: ``1`` an integer, ``1.0`` a double, ``true`` a bool,
  ``[..]`` a list); without ``node:`` it is for every node (``/**``);
- ``--params-file FILE``: a ROS 2 parameter file, read at once, into the same store;
- ``--log-level``, ``--log-file-name``, ``--log-config-file``, ``-e``/``--enclave``,
  ``--enable-``/``--disable-`` ``stdout-logs``/``rosout-logs``/``external-lib-logs``:
  taken as rcl takes them (the log level is checked), kept, and not used by the bridge.

A flag without its value, or a value rcl refuses, is an error (``RosArgumentsError``,
"Couldn't parse …" in rcl). Anything else inside a block is an unknown ROS argument,
which rclpy refuses at start (``UnknownROSArgsError``): ``parse_arguments`` raises
naming them. Outside the blocks, an argument that is a remap rule is one (rcl's
deprecated form, with a warning); the rest is given back, in order, for the program's
own parser.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from wcdrive.errors import WcdriveFileError
from wcdrive.ros2.names import RemapRule, RosNameError, parse_remap
from wcdrive.ros2.params import ParameterError, ParameterStore, parse_param_rule

__all__ = ["RosArguments", "RosArgumentsError", "parse_arguments"]

ROS_ARGS, END = "--ros-args", "--"
#: rcutils' severities, as ``--log-level`` takes them (any case).
SEVERITIES = ("UNSET", "DEBUG", "INFO", "WARN", "ERROR", "FATAL")
#: What ``--enable-``/``--disable-`` turn on and off.
LOG_FLAGS = ("stdout-logs", "rosout-logs", "external-lib-logs")


class RosArgumentsError(WcdriveFileError):
    """ROS arguments that rcl (or rclpy, for unknown ones) refuses."""


@dataclass
class RosArguments:
    """What ``parse_arguments`` found: the remap rules in order, the parameters (files
    and ``-p`` rules merged in order, as rcl merges them) and the files read, the
    logging and enclave settings, and the deprecated remap rules seen outside a block
    (``warnings``)."""

    remaps: list[RemapRule] = field(default_factory=list)
    parameters: ParameterStore = field(default_factory=ParameterStore)
    param_files: list[str] = field(default_factory=list)
    log_levels: list[str] = field(default_factory=list)
    log_file_name: str | None = None
    log_config_file: str | None = None
    enclave: str | None = None
    log_flags: dict[str, bool] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def _log_level(text: str) -> bool:
    """Whether ``text`` is a ``--log-level`` rcl takes: ``SEVERITY`` or ``logger:=SEVERITY``."""
    name, sep, level = text.rpartition(":=")
    if sep and not name:
        return False
    return (level if sep else text).upper() in SEVERITIES


def parse_arguments(argv: list[str]) -> tuple[RosArguments, list[str]]:
    """(the ROS arguments, the other arguments in order) of ``argv`` (the program name
    not included); ``RosArgumentsError`` as rcl and rclpy refuse (module docstring)."""
    ros = RosArguments()
    rest: list[str] = []
    unknown: list[str] = []
    inside = False
    i = 0
    while i < len(argv):
        arg = argv[i]
        if not inside:
            if arg == ROS_ARGS:
                inside = True
            else:
                try:
                    rule = parse_remap(arg)
                except RosNameError:
                    rest.append(arg)
                else:
                    ros.remaps.append(rule)
                    ros.warnings.append(f"found remap rule {arg!r}: this syntax is deprecated, use "
                                        f"'{ROS_ARGS} --remap {arg}' instead")
            i += 1
            continue
        if arg == ROS_ARGS:
            i += 1
            continue
        if arg == END:
            inside = False
            i += 1
            continue
        if arg in ("-p", "--param", "-r", "--remap", "--params-file", "--log-level", "--log-file-name",
                   "--log-config-file", "-e", "--enclave"):
            if i + 1 >= len(argv):
                raise RosArgumentsError(f"couldn't parse trailing {arg} flag: it needs a value")
            _take(ros, arg, argv[i + 1])
            i += 2
            continue
        flag = _log_flag(arg)
        if flag is not None:
            ros.log_flags[flag[0]] = flag[1]
            i += 1
            continue
        unknown.append(arg)
        i += 1
    if unknown:
        raise RosArgumentsError(f"found unknown ROS arguments: {unknown} (known: -r/--remap, -p/--param, "
                                "--params-file, --log-level, --log-file-name, --log-config-file, "
                                "-e/--enclave, --enable-/--disable-stdout-logs, rosout-logs, "
                                "external-lib-logs; a block ends at '--')")
    return ros, rest


def _take(ros: RosArguments, flag: str, value: str) -> None:
    """One flag with its value (``rcl_parse_arguments``' branches)."""
    try:
        if flag in ("-p", "--param"):
            node, name, yaml_value = parse_param_rule(value)
            ros.parameters.set_rule(node, name, yaml_value)
        elif flag in ("-r", "--remap"):
            ros.remaps.append(parse_remap(value))
        elif flag == "--params-file":
            ros.parameters.parse_file(value)
            ros.param_files.append(value)
        elif flag == "--log-level":
            if not _log_level(value):
                raise RosArgumentsError(f"{value!r} is not a severity ({', '.join(SEVERITIES)}, "
                                        "or logger:=SEVERITY)")
            ros.log_levels.append(value)
        elif flag == "--log-file-name":
            ros.log_file_name = value
        elif flag == "--log-config-file":
            ros.log_config_file = value
        else:
            ros.enclave = value
    except (RosNameError, ParameterError, RosArgumentsError) as exc:
        text = str(exc)
        where = "" if text.startswith(f"{flag} {value}:") else f"'{flag} {value}': "  # a file names itself
        raise RosArgumentsError(f"couldn't parse {where}{text}") from None


def _log_flag(arg: str) -> tuple[str, bool] | None:
    """(``stdout-logs``/``rosout-logs``/``external-lib-logs``, enabled) of an
    ``--enable-``/``--disable-`` flag, or None."""
    for prefix, enabled in (("--enable-", True), ("--disable-", False)):
        if arg.startswith(prefix) and arg[len(prefix):] in LOG_FLAGS:
            return arg[len(prefix):], enabled
    return None
