"""Makes wcdrive's pyserial URL handlers (``wcsim://``, ``wcavr://``, ``wccan://``)
visible to any program that uses pyserial, without importing wcdrive first:
``python -m serial.tools.miniterm wcsim://``.

pyserial imports ``serial.urlhandler.protocol_<scheme>`` for a URL. The
``wcdrive-serial-urls.pth`` file installed beside this module puts a finder on
``sys.meta_path`` at interpreter start that answers that import, for wcdrive's
schemes only, with ``wcdrive.transports.urlhandler.protocol_<scheme>``. Nothing is imported
until a program opens such a URL.

PYTEST_DONT_REWRITE: the .pth imports this module before pytest can (pytest would
otherwise warn, when it loads wcdrive's plugin, that it cannot rewrite it).
"""

from __future__ import annotations

import importlib
import sys
from importlib.machinery import ModuleSpec

SCHEMES = ("wcsim", "wcavr", "wccan", "wceddie")
_PREFIX = "serial.urlhandler.protocol_"


class _Alias:
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
        if not name.startswith(_PREFIX) or name[len(_PREFIX):] not in SCHEMES:
            return None
        return ModuleSpec(name, _Alias("wcdrive.transports.urlhandler.protocol_" + name[len(_PREFIX):]))


def install() -> None:
    if not any(isinstance(f, SerialUrlFinder) for f in sys.meta_path):
        sys.meta_path.append(SerialUrlFinder())
