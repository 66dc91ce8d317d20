"""The same examples in every test process: hypothesis' pool of the project's own
constants, taken once from every module of the library and then held.

A derandomized test draws its examples from a seed that follows from the test, and now
and then (5 % of draws) a constant from a pool: hypothesis' own, and the literals of
every *local* module in ``sys.modules`` at the draw (recent hypothesis, 6.155 here:
``hypothesis.internal.conjecture.providers``). Which library modules a pytest-xdist
worker has imported by the time a test runs depends on which tests it ran before, and
that depends on the run's timing; so the same code drew different examples in two runs
(the thorough CI drew a lock-step trace no local run could replay). Here every module
of ``wcdrive`` and ``wcdrive.hil`` is imported before the first test, the pool is taken
then, and hypothesis is given that pool from then on, whatever a test imports later
(a benchmark loaded from its file, a module a test writes).

The hold replaces ``providers._get_local_constants``, hypothesis' internal hook (a
hypothesis without it has no such pool, or keeps it elsewhere:
tests/meta/test_hypothesis_constants.py shows whether the examples still hold).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import warnings

import wcdrive
import wcdrive.hil

#: Modules the walk finds that are not imported, and why.
NOT_IMPORTED = {
    "wcdrive.__main__": "runs the command line when imported (sys.exit(main())); it defines nothing",
    "wcdrive.plant._chair_kernel": "a C library that wcdrive._util.native loads with ctypes "
                                   "(there when built), not a Python extension module",
    "wcdrive.plant._raycast": "a C library that wcdrive._util.native loads with ctypes "
                              "(there when built), not a Python extension module",
}


def project_modules() -> list[str]:
    """Every module of ``wcdrive`` and of ``wcdrive.hil`` (``hil/``), by pkgutil; a
    package that cannot be imported is an error."""
    def onerror(name: str) -> None:
        raise AssertionError(f"cannot import package {name}") from sys.exc_info()[1]

    names: list[str] = []
    for package in (wcdrive, wcdrive.hil):
        names.append(package.__name__)
        names += [info.name for info in pkgutil.walk_packages(package.__path__, package.__name__ + ".",
                                                              onerror=onerror)]
    return list(dict.fromkeys(names))


def import_project() -> None:
    """Imports every module ``project_modules`` lists but those in ``NOT_IMPORTED`` (the
    old names' warnings hushed: their own tests pop them and import them afresh)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for name in project_modules():
            if name not in NOT_IMPORTED:
                importlib.import_module(name)


def pin_local_constants() -> int:
    """Imports the project, takes hypothesis' pool of local constants and holds it for
    the rest of the process. Returns the pool's size."""
    from hypothesis.internal.conjecture import providers

    import_project()
    hook = getattr(providers, "_get_local_constants", None)
    if hook is None:
        return 0
    pool = hook()

    def held() -> object:
        return pool

    providers._get_local_constants = held
    return len(pool)
