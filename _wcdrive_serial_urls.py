"""Makes wcdrive's pyserial URL handlers (``wcsim://``, ``wcavr://``, ``wccan://``, and
those of robot plugins, such as ``wceddie://``) visible to any program that uses
pyserial, without importing wcdrive first: ``python -m serial.tools.miniterm wcsim://``.

pyserial imports ``serial.urlhandler.protocol_<scheme>`` for a URL. The
``wcdrive-serial-urls.pth`` file installed beside this module puts a finder on
``sys.meta_path`` at interpreter start that answers that import, for the schemes
registered in the ``wcdrive.serial_urls`` entry-point group only (the one registration
path: name = the scheme, value = the handler module), with that module. Nothing is
imported until a program opens such a URL.

PYTEST_DONT_REWRITE: the .pth imports this module before pytest can (pytest would
otherwise warn, when it loads wcdrive's plugin, that it cannot rewrite it).
"""

from __future__ import annotations

import importlib
import importlib.abc
import sys
from importlib.machinery import ModuleSpec

_GROUP = "wcdrive.serial_urls"
_PREFIX = "serial.urlhandler.protocol_"


def handlers() -> dict[str, str]:
    """The registered schemes and their handler modules (the entry-point group)."""
    from importlib.metadata import entry_points

    return {ep.name: ep.value for ep in entry_points(group=_GROUP)}


class _Alias(importlib.abc.Loader):
    """Loader: the handler module of wcdrive, under pyserial's name for it."""

    def __init__(self, target: str) -> None:
        self.target = target

    def create_module(self, spec: ModuleSpec):
        return importlib.import_module(self.target)

    def exec_module(self, module) -> None:
        pass


class SerialUrlFinder:
    @staticmethod
    def find_spec(name: str, path=None, target=None) -> ModuleSpec | None:
        if not name.startswith(_PREFIX):
            return None
        target = handlers().get(name[len(_PREFIX):])
        return None if target is None else ModuleSpec(name, _Alias(target))


def install() -> None:
    if not any(isinstance(f, SerialUrlFinder) for f in sys.meta_path):
        sys.meta_path.append(SerialUrlFinder())
