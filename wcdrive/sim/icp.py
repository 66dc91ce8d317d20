"""Deprecated: moved to ``wcdrive.navigation.icp``, beside the other navigation helpers
(this name is kept for one release and warns; every name resolves to the new module's)."""

from __future__ import annotations

import warnings
from typing import Any

from wcdrive.navigation import icp as _moved

warnings.warn("wcdrive.sim.icp moved to wcdrive.navigation.icp", DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> Any:
    return getattr(_moved, name)
