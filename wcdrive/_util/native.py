"""Compiles small C helpers from source on first use and loads them: shared libraries
with ctypes (``load``), CPython extension modules with importlib (``load_extension``).

The library is built with the system C compiler into a cache directory keyed by the
source's hash (``wcdrive._util.resources.cache_dir()``); nothing prebuilt ships.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import importlib.util
import os
import subprocess
import sys
import sysconfig
import threading
from pathlib import Path
from types import ModuleType

from wcdrive._util.resources import cache_dir


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
    # a name of its own per process and thread: two builds of one source at once (Dask
    # workers in threads, pytest-xdist processes) must not write the same file
    tmp = target.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
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


def load_extension(source: Path, name: str, flags: tuple[str, ...] = ("-O2",)) -> ModuleType:
    """A CPython extension module ``name`` (its ``PyInit_<name>``) built from ``source``
    against this interpreter's headers (``sysconfig``), imported from the cache; the
    interpreter's ABI tag is part of the build's hash. Raises ``BuildError`` when it
    cannot be built (no compiler, no ``Python.h``) or loaded."""
    include = sysconfig.get_paths()["include"]
    if not (Path(include) / "Python.h").exists():
        raise BuildError(f"no Python.h in {include}: apt-get install python3-dev")
    abi = str(sysconfig.get_config_var("EXT_SUFFIX") or sys.implementation.cache_tag)
    path = compile_shared(source, name, (), (*flags, f"-I{include}", f"-DWCDRIVE_ABI=\"{abi}\""))
    loader = importlib.machinery.ExtensionFileLoader(name, str(path))
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    if spec is None:
        raise BuildError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    try:
        loader.exec_module(module)
    except ImportError as exc:
        raise BuildError(f"cannot load {path}: {exc}") from exc
    return module
