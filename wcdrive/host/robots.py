"""The robot registry: the robots besides the chair that ``wcdrive.connect`` drives, each
a plugin found through the ``wcdrive.robots`` entry-point group, as python-can finds
its interfaces through ``can.interface``.

A robot is one package plus one entry point. The entry point names a ``RobotEntry``:
its name, the URL prefixes it answers (``eddie+sim://``, ``eddie://``) and how it
connects. Its pyserial URL handler (a simulated board, ``wceddie://``), if it has one,
is registered through the ``wcdrive.serial_urls`` group, the one path by which every
``wc*://`` scheme reaches pyserial (``_wcdrive_serial_urls``)::

    [project.entry-points."wcdrive.robots"]
    eddie = "wcdrive.eddie.plugin:ROBOT"
    [project.entry-points."wcdrive.serial_urls"]
    wceddie = "wcdrive.eddie.serial_url"

The chair itself is not a plugin: it is what ``connect`` opens for every other URL.
Two plugins claiming one prefix is a ``WcdriveError`` naming both; a plugin whose
entry point does not load, or does not name a ``RobotEntry``, is one naming it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from wcdrive.errors import WcdriveError
from wcdrive.host.robot import Robot
from wcdrive.transports.port import Port

__all__ = ["ROBOTS_GROUP", "SERIAL_URLS_GROUP", "Link", "RobotEntry", "entry_for", "extra", "registered"]

ROBOTS_GROUP = "wcdrive.robots"
SERIAL_URLS_GROUP = "wcdrive.serial_urls"


@dataclass(frozen=True)
class Link:
    """What ``connect`` hands a plugin to open its link with: ``open_url`` (a pyserial
    URL, its errors named), ``open_device`` (a serial device path, opened exclusively)
    and ``wrap`` (the recording and ROS taps ``connect`` was asked for)."""

    open_url: Callable[[str], Port]
    open_device: Callable[[str], Port]
    wrap: Callable[[Port], Port]


@dataclass(frozen=True)
class RobotEntry:
    """A robot plugin: ``name``, the URL ``prefixes`` it answers, and ``connect(url,
    link, **options) -> Robot``. ``extras``: whatever else the plugin offers by name
    for the tools (its robot class; its scenario runner or simulated board as a
    ``"module"`` or ``"module:attribute"`` path, imported only when asked for:
    ``extra``)."""

    name: str
    prefixes: tuple[str, ...]
    connect: Callable[..., Robot]
    description: str = ""
    extras: Mapping[str, Any] = field(default_factory=dict)


def registered() -> dict[str, RobotEntry]:
    """Every installed robot plugin, by name (loaded on each call: a plugin installed
    meanwhile is seen)."""
    out: dict[str, RobotEntry] = {}
    owner: dict[str, str] = {}
    for ep in entry_points(group=ROBOTS_GROUP):
        try:
            entry = ep.load()
        except Exception as exc:
            raise WcdriveError(f"the robot plugin {ep.name!r} ({ep.value}) does not load: {exc}") from exc
        if not isinstance(entry, RobotEntry):
            raise WcdriveError(f"the robot plugin {ep.name!r} ({ep.value}) is not a "
                               f"wcdrive.host.robots.RobotEntry but {type(entry).__name__}")
        for prefix in entry.prefixes:
            if prefix in owner and owner[prefix] != entry.name:
                raise WcdriveError(f"the robot plugins {owner[prefix]!r} and {entry.name!r} both "
                                   f"claim {prefix!r}")
            owner[prefix] = entry.name
        out[entry.name] = entry
    return out


def entry_for(url: str) -> RobotEntry | None:
    """The plugin whose prefix ``url`` starts with (the longest), or None: the chair's."""
    best: tuple[int, RobotEntry] | None = None
    for entry in registered().values():
        for prefix in entry.prefixes:
            if url.startswith(prefix) and (best is None or len(prefix) > best[0]):
                best = (len(prefix), entry)
    return None if best is None else best[1]


def extra(robot: str, key: str) -> Any:
    """The plugin ``robot``'s extra ``key``: the object itself, or what its
    ``"module"``/``"module:attribute"`` path names, imported now. A robot or key that is
    not registered is a ``WcdriveError`` naming what is."""
    entries = registered()
    if robot not in entries:
        raise WcdriveError(f"no robot plugin {robot!r}; installed: {', '.join(sorted(entries)) or 'none'}")
    extras = entries[robot].extras
    if key not in extras:
        raise WcdriveError(f"the robot plugin {robot!r} offers no {key!r}; it offers: "
                           f"{', '.join(sorted(extras)) or 'nothing'}")
    value = extras[key]
    if not isinstance(value, str):
        return value
    module, _, attribute = value.partition(":")
    loaded = importlib.import_module(module)
    return getattr(loaded, attribute) if attribute else loaded
