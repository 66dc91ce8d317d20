"""Compiles small C helpers from source on first use and loads them with ctypes.

The library is built with the system C compiler into a cache directory keyed by the
source's hash (``wcdrive.resources.cache_dir()``); nothing prebuilt ships.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
from pathlib import Path

from wcdrive.resources import cache_dir


class BuildError(RuntimeError):
    """A C helper could not be compiled; the message says what to install."""


def compile_shared(source: Path, name: str, libs: tuple[str, ...] = (),
                   flags: tuple[str, ...] = ("-O2",)) -> Path:
    """Path of ``lib<name>-<hash>.so`` built from ``source`` (compiled now if needed)."""
    text = source.read_bytes()
    digest = hashlib.sha256(text + " ".join(flags + libs).encode()).hexdigest()[:16]
    target = cache_dir() / f"lib{name}-{digest}.so"
    if target.exists():
        return target
    cc = os.environ.get("CC", "gcc")
    tmp = target.with_suffix(f".{os.getpid()}.tmp")
    cmd = [cc, "-shared", "-fPIC", "-Wall", *flags, "-o", str(tmp), str(source), *libs]
    try:
        result = subprocess.run(cmd, capture_output=True, text=True)
    except FileNotFoundError as exc:
        raise BuildError(f"no C compiler ({cc}): apt-get install gcc") from exc
    if result.returncode != 0:
        raise BuildError(f"compiling {source.name} failed:\n{' '.join(cmd)}\n{result.stderr}")
    os.replace(tmp, target)
    return target


def load(source: Path, name: str, libs: tuple[str, ...] = (),
         flags: tuple[str, ...] = ("-O2",)) -> ctypes.CDLL:
    """``compile_shared`` then load the library with ctypes."""
    return ctypes.CDLL(str(compile_shared(source, name, libs, flags)))
