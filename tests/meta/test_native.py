"""``wcdrive._util.native``: the helpers the install built are used only while they match
the source; a helper built on first use is built once per source, safely from several
threads at once (Dask workers run simulations in threads; each may be first to need
one)."""

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


HELPERS = [("wcdrive.avr._f32_fast", "avr/csrc/f32_fast.c", native.prebuilt),
           ("wcdrive.firmware._tick_fast", "firmware/csrc/tick_fast.c", native.prebuilt),
           ("wcdrive.plant._chair_kernel", "plant/csrc/chair_kernel.c", native.prebuilt_library),
           ("wcdrive.plant._raycast", "plant/csrc/raycast.c", native.prebuilt_library)]


@pytest.mark.parametrize(("module", "source", "find"), HELPERS)
def test_the_install_built_each_helper_and_it_is_used_only_for_its_own_source(
        module: str, source: str, find, tmp_path: Path) -> None:
    import wcdrive

    real = Path(wcdrive.__file__).parent / source
    assert find(module, real) is not None, f"the install did not build {module} (setup.py NATIVE)"
    edited = tmp_path / real.name
    edited.write_bytes(real.read_bytes() + b"\n/* edited since the install */\n")
    assert find(module, edited) is None          # a changed C file is compiled anew, never stale


def test_every_helper_this_process_loaded_says_how() -> None:
    from wcdrive.avr import f32
    from wcdrive.firmware import tick_fast
    from wcdrive.plant.chair import load_kernel
    from wcdrive.plant.raycast import load_raycast

    assert f32.fast is not None and tick_fast.fast is not None and load_kernel() is not None
    assert load_raycast() is not None
    assert set(native.paths()) >= {"binary32", "control tick", "plant kernel", "ray cast"}
