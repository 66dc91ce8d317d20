"""The C helpers (the binary32 arithmetic, the control tick, the plant's kernel): built
when wcdrive is installed, else compiled on first use, else absent.

``pip install`` builds each helper (setup.py's ``ext_modules``) into the package, and
``prebuilt``/``prebuilt_library`` find it there. Where the install found no compiler,
``load``/``load_extension`` compile the source with the system C compiler into a cache
directory keyed by the source's hash (``wcdrive._util.resources.cache_dir()``). Each
helper's loader records how it was had (``record``); ``paths()`` tells them, for
``wcdrive --version``.
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
from wcdrive.errors import WcdriveError


class BuildError(WcdriveError, RuntimeError):
    """A C helper could not be compiled; the message says what to install."""


#: How each helper was had: "built at install", "built at first use", or why it is
#: Python (``record``).
_HOW: dict[str, str] = {}


def record(helper: str, how: str) -> None:
    """Notes how ``helper`` was loaded (or why not), for ``paths``."""
    _HOW[helper] = how


def paths() -> dict[str, str]:
    """Each C helper loaded so far and how: ``{"binary32": "built at install", ...}``."""
    return dict(_HOW)


def _prebuilt_path(module: str, source: Path) -> str | None:
    """Where the install built ``module``, if it did and from ``source`` as it is now
    (the hash setup.py wrote beside it): a checkout whose C changed since the install
    compiles the new source instead of running the old build."""
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    if spec is None or spec.origin is None or not spec.origin.endswith(
            tuple(importlib.machinery.EXTENSION_SUFFIXES)):
        return None
    try:
        recorded = Path(spec.origin + ".sha256").read_text().strip()
    except OSError:
        return None
    return spec.origin if recorded == hashlib.sha256(source.read_bytes()).hexdigest() else None


def prebuilt(module: str, source: Path) -> ModuleType | None:
    """The extension module ``module`` (``wcdrive.avr._f32_fast``) as the install built it
    from ``source``, or None where it did not (or built it from another source)."""
    if _prebuilt_path(module, source) is None:
        return None
    try:
        return importlib.import_module(module)
    except ImportError:
        return None


def prebuilt_library(module: str, source: Path) -> ctypes.CDLL | None:
    """The shared library the install built from ``source`` under the name ``module``
    (loaded with ctypes: it is C with no Python module in it), or None."""
    path = _prebuilt_path(module, source)
    if path is None:
        return None
    try:
        return ctypes.CDLL(path)
    except OSError:
        return None


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


def library(module: str, source: Path, name: str, libs: tuple[str, ...] = (),
            flags: tuple[str, ...] = ("-O2",)) -> tuple[ctypes.CDLL, str]:
    """The shared library the install built from ``source`` as ``module``, else ``load``
    compiles it now; with how it was had ("built at install" or "built at first use").
    Raises ``BuildError`` as ``load`` does."""
    lib = prebuilt_library(module, source)
    if lib is not None:
        return lib, "built at install"
    return load(source, name, libs, flags), "built at first use"


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
