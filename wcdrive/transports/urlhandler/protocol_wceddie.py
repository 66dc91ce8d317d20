"""Deprecated: ``wceddie://``'s handler is the Eddie plugin's (``wcdrive.eddie.serial_url``),
which pyserial reaches through the ``wcdrive.serial_urls`` entry point. This name is
kept for one release and warns; it loads the registered handler by name."""

from __future__ import annotations

import importlib
import warnings

from _wcdrive_serial_urls import handlers

warnings.warn("wcdrive.transports.urlhandler.protocol_wceddie moved to the Eddie plugin's "
              "wcdrive.eddie.serial_url (the wcdrive.serial_urls entry point 'wceddie')",
              DeprecationWarning, stacklevel=2)

_handler = importlib.import_module(handlers()["wceddie"])
Serial = _handler.Serial
USAGE = _handler.USAGE
OPTIONS = _handler.OPTIONS
