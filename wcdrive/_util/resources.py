"""Where wcdrive's non-Python files are: the firmware sources, the protocol spec and its
vectors, and the per-user cache that builds go to.

In a wheel they are package data under ``wcdrive._data`` (``importlib.resources``);
in a checkout (editable install) the same packages map onto the repository's own
``firmware/`` and ``protocol/`` folders. Builds never write into either: they go to
``cache_dir()`` (``$WCDRIVE_CACHE``, else ``$XDG_CACHE_HOME/wcdrive``, else
``~/.cache/wcdrive``).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

__all__ = ["cache_dir", "firmware_dir", "protocol_dir"]


#: The checkout this module sits in, when it is one (an editable install or a test run
#: from the repository): setuptools' editable finder does not map data-only packages.
_CHECKOUT = Path(__file__).resolve().parents[2]


def _package_dir(package: str, checkout_folder: str, marker: str) -> Path:
    """The folder of a data package as a real path: the wheel's package data, else the
    checkout's own folder. ``marker`` is a file the folder holds: the data packages are
    namespace packages, whose ``files()`` is a multiplexed path; a file in it is real."""
    try:
        path = Path(str(resources.files(package).joinpath(marker))).parent
    except ModuleNotFoundError:
        path = _CHECKOUT / checkout_folder
    if not (path / marker).is_file():
        raise FileNotFoundError(f"{package} ({checkout_folder}/{marker}) is missing: reinstall wcdrive")
    return path


def protocol_dir() -> Path:
    """``protocol/``: spec.toml, vectors.toml, wcdrive.dbc, PROTOCOL.md, CAN.md."""
    return _package_dir("wcdrive._data.protocol", "protocol", "spec.toml")


def firmware_dir(sketch: str = "final_control") -> Path:
    """A sketch folder of ``firmware/`` (``final_control`` or ``fpcheck``)."""
    return _package_dir(f"wcdrive._data.firmware.{sketch}", f"firmware/{sketch}", f"{sketch}.ino")


def cache_dir(*parts: str) -> Path:
    """A folder in the per-user build cache (created)."""
    base = os.environ.get("WCDRIVE_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "wcdrive")
    path = Path(base, *parts)
    path.mkdir(parents=True, exist_ok=True)
    return path
