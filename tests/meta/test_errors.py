"""One root for everything wcdrive raises: every exception class defined in the library
(and in the harness it ships as ``wcdrive.hil``) derives from
``wcdrive.errors.WcdriveError``, so ``except WcdriveError`` catches anything wcdrive
raised; each keeps its old built-in base beside it, so ``except ValueError`` (a file or
configuration error: ``WcdriveFileError``) and ``except RuntimeError`` still work."""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import warnings
from pathlib import Path
from types import ModuleType

import pytest

from tests.support.hypothesis_constants import NOT_IMPORTED, project_modules
from wcdrive.errors import WcdriveError, WcdriveFileError

#: Exception classes that deliberately stay outside ``WcdriveError``, and why.
NOT_WCDRIVE_ERRORS = {
    "wcdrive.tools.bench.Interrupted": "Ctrl-C during `bench run`: a KeyboardInterrupt carrying the "
                                       "recording, kept outside Exception so that `except Exception` "
                                       "(and `except WcdriveError`) never swallows Ctrl-C",
}


@pytest.fixture(scope="module")
def imported() -> dict[str, ModuleType]:
    # the old names kept for a release warn when imported, by design
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return {name: importlib.import_module(name) for name in project_modules() if name not in NOT_IMPORTED}


def _qualified(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def wcdrive_exceptions() -> list[type[BaseException]]:
    """Every live exception class whose module is wcdrive's or the harness's."""
    found: dict[type, None] = {}
    todo: list[type] = [BaseException]
    while todo:
        cls = todo.pop()
        for sub in cls.__subclasses__():
            if sub not in found:
                found[sub] = None
                todo.append(sub)
    return sorted((c for c in found if c.__module__.startswith(("wcdrive", "hil"))), key=_qualified)


def test_every_module_is_imported_or_listed_with_its_reason(imported: dict[str, ModuleType]) -> None:
    names = project_modules()
    assert len(imported) > 100 and "wcdrive.hil.lockstep" in imported and "wcdrive.tools.sweep" in imported
    assert set(names) == set(imported) | (set(names) & set(NOT_IMPORTED))
    for name in set(names) & set(NOT_IMPORTED):
        if name.endswith("__main__"):
            continue
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin is not None, name
        assert spec.origin.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)), spec.origin


def test_every_exception_wcdrive_defines_is_a_wcdrive_error(imported: dict[str, ModuleType]) -> None:
    exceptions = wcdrive_exceptions()
    assert len(exceptions) > 20
    assert {_qualified(c) for c in exceptions} >= set(NOT_WCDRIVE_ERRORS)
    offenders = [f"{_qualified(c)}({', '.join(b.__name__ for b in c.__bases__)})" for c in exceptions
                 if not issubclass(c, WcdriveError) and _qualified(c) not in NOT_WCDRIVE_ERRORS]
    assert offenders == []


def test_the_exceptions_left_out_are_not_exceptions_at_all(imported: dict[str, ModuleType]) -> None:
    """What stays outside ``WcdriveError`` is outside ``Exception`` too (Ctrl-C)."""
    by_name = {_qualified(c): c for c in wcdrive_exceptions()}
    for name in NOT_WCDRIVE_ERRORS:
        assert not issubclass(by_name[name], Exception), name


def test_file_errors_are_value_errors() -> None:
    from wcdrive.boards.simavr.bootloader_mega import HexError
    from wcdrive.plant.params import ChairFileError
    from wcdrive.plant.rosmap import MapFileError
    from wcdrive.plant.world import WorldError
    from wcdrive.sim.scenario import ScenarioError
    from wcdrive.tools.identify import RecordingError
    from wcdrive.tools.replay import ReplayError
    from wcdrive.tools.sweep import SpecError

    assert issubclass(WcdriveFileError, WcdriveError) and issubclass(WcdriveFileError, ValueError)
    for cls in (ChairFileError, WorldError, MapFileError, ScenarioError, SpecError, RecordingError,
                ReplayError, HexError):
        assert issubclass(cls, WcdriveFileError), cls


def test_each_error_keeps_its_old_base() -> None:
    from wcdrive._util.native import BuildError
    from wcdrive.boards.simavr.virtual_mega import HarnessError
    from wcdrive.protocol.can_frames import CanCodecError

    for cls, old in ((HarnessError, RuntimeError), (BuildError, RuntimeError), (CanCodecError, ValueError)):
        assert issubclass(cls, WcdriveError) and issubclass(cls, old), cls


def test_a_malformed_scenario_is_a_wcdrive_error_and_a_value_error(tmp_path: Path) -> None:
    from wcdrive.sim import scenario

    bad = tmp_path / "bad.toml"
    bad.write_text("[[segment]]\ncmdvel = [0.5, 0.0]\n")             # no duration
    with pytest.raises(WcdriveError, match="duration") as caught:
        scenario.load(str(bad))
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, WcdriveFileError)
    with pytest.raises(ValueError):
        scenario.load(str(bad))


def test_a_malformed_chair_file_is_a_wcdrive_error_and_a_value_error(tmp_path: Path) -> None:
    from wcdrive.plant.params import load_chair

    bad = tmp_path / "chair.toml"
    bad.write_text("[chair]\nno_such_field = 1.0\n")
    with pytest.raises(WcdriveError, match="no_such_field") as caught:
        load_chair(bad)
    assert isinstance(caught.value, ValueError)
    bad.write_text("not toml [")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_chair(bad)


def test_the_command_line_status_of_each_error_is_unchanged() -> None:
    """A file error is still a usage error (2); a virtual board that broke is still an
    internal error (70), not a usage error, though it is now a WcdriveError."""
    from wcdrive.boards.simavr.virtual_mega import HarnessError
    from wcdrive.plant.params import ChairFileError
    from wcdrive.protocol.can_frames import CanCodecError
    from wcdrive.tools import console

    assert console.exit_code(ChairFileError("chair.toml: no [chair] table")) == console.USAGE
    assert console.exit_code(CanCodecError("no counterpart")) == console.USAGE
    assert console.exit_code(HarnessError("the AVR core stopped (crashed)")) == console.INTERNAL


def test_the_codec_error_is_a_message_not_an_exception() -> None:
    """``wcdrive.protocol.codec.Error`` is a parsed ``ERR:`` line."""
    from wcdrive.protocol.codec import Error

    assert not issubclass(Error, BaseException)
    assert "not an exception" in (Error.__doc__ or "")
