"""``wcdrive._util.native`` builds a helper once per source, safely from several threads at once
(Dask workers run simulations in threads; each may be first to need a helper)."""

from __future__ import annotations

import ctypes
import threading
from pathlib import Path

import pytest

from wcdrive._util import native


def test_threads_building_one_source_at_once_all_load_it(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("WCDRIVE_CACHE", str(tmp_path / "cache"))
    source = tmp_path / "answer.c"
    # big enough that the builds overlap
    body = "\n".join(f"int f{i}(int x) {{ return x * {i} + {i % 7}; }}" for i in range(1200))
    source.write_text(body + "\nint answer(void) { return 42; }\n")
    results: list[object] = []
    barrier = threading.Barrier(6)

    def build() -> None:
        barrier.wait()
        try:
            lib = native.load(source, "answer")
            lib.answer.restype = ctypes.c_int
            results.append(lib.answer())
        except Exception as exc:             # the test reports what went wrong
            results.append(exc)

    threads = [threading.Thread(target=build) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert results == [42] * 6
    assert not list((tmp_path / "cache").glob("*.tmp"))


def test_a_compile_error_says_what_failed(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("WCDRIVE_CACHE", str(tmp_path / "cache"))
    source = tmp_path / "broken.c"
    source.write_text("int broken(void) { return }\n")
    with pytest.raises(native.BuildError, match=r"compiling broken\.c failed"):
        native.load(source, "broken")
