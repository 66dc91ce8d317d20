"""Packaging details that pyproject.toml cannot say.

- ``hil/`` (the verification harness) ships inside the wheel as ``wcdrive.hil``;
  ``firmware/`` and ``protocol/`` ship as package data under ``wcdrive._data``, so a
  wheel installed anywhere can build the firmware and load the spec.
- ``wcdrive-serial-urls.pth`` goes to site-packages beside ``_wcdrive_serial_urls.py``,
  for wheels and editable installs alike: pyserial then finds ``wcsim://``,
  ``wcavr://``, ``wccan://`` and ``wceddie://`` (every scheme of the
  ``wcdrive.serial_urls`` entry points) without importing wcdrive first.
- The C helpers (``NATIVE``) are built at install. Without a C compiler (or Python's
  headers) the install still succeeds and says so; wcdrive then compiles them on first
  use where it can, and runs the Python paths where it cannot (``wcdrive --version``
  tells which).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py
from setuptools.command.editable_wheel import editable_wheel

ROOT = Path(__file__).resolve().parent
PTH = "wcdrive-serial-urls.pth"


def python_packages(top: str, name: str) -> list[str]:
    return [name + "".join("." + part for part in d.relative_to(ROOT / top).parts)
            for d in sorted([ROOT / top, *(ROOT / top).rglob("*")])
            if d.is_dir() and (d / "__init__.py").exists()]


#: Non-Python folders shipped as data: package name -> folder in the checkout.
DATA = {
    "wcdrive._data.protocol": "protocol",
    "wcdrive._data.firmware.final_control": "firmware/final_control",
    "wcdrive._data.firmware.fpcheck": "firmware/fpcheck",
}
DATA_FILES = ["*.toml", "*.md", "*.dbc", "*.ino", "*.h", "Makefile"]


#: The C helpers. -ffp-contract=off: each binary32 operation rounds once, as on the AVR
#: (no fused multiply-add), which the port's bit-exactness needs.
_FLAGS = ["-O2", "-ffp-contract=off"]


def _numpy_random() -> dict[str, list]:
    """The ray cast's build options for drawing a lidar's noise with numpy's own C
    generators (``libnpyrandom.a``, as wcdrive.plant.raycast.numpy_random finds them);
    none where the build has no such numpy."""
    try:
        import numpy
    except ImportError:
        return {}
    include = Path(numpy.get_include())
    lib = Path(numpy.__file__).parent / "random" / "lib" / "libnpyrandom.a"
    if not ((include / "numpy" / "random" / "bitgen.h").exists() and lib.exists()):
        return {}
    return {"define_macros": [("WC_NPYRANDOM", "1")], "include_dirs": [str(include)],
            "extra_objects": [str(lib)]}


NATIVE = [
    Extension("wcdrive.avr._f32_fast", ["wcdrive/avr/csrc/f32_fast.c"], extra_compile_args=_FLAGS,
              optional=True),
    Extension("wcdrive.firmware._tick_fast", ["wcdrive/firmware/csrc/tick_fast.c"],
              extra_compile_args=_FLAGS, optional=True),
    # plain C loaded with ctypes (no Python module in it), built the same way
    Extension("wcdrive.plant._chair_kernel", ["wcdrive/plant/csrc/chair_kernel.c"],
              extra_compile_args=_FLAGS, libraries=["m"], optional=True),
    Extension("wcdrive.plant._raycast", ["wcdrive/plant/csrc/raycast.c"],
              extra_compile_args=_FLAGS, libraries=["m", "pthread"], optional=True, **_numpy_random()),
]


class OptionalBuildExt(build_ext):
    """Builds the C helpers; a helper that cannot be built is reported, not fatal."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:
            self._skipped("all C helpers", exc)

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:
            self._skipped(ext.name, exc)
            return
        # the source's hash beside the helper: wcdrive uses a helper only while it was
        # built from the source it ships (wcdrive._util.native.prebuilt)
        built = Path(self.get_ext_fullpath(ext.name))
        digest = hashlib.sha256((ROOT / ext.sources[0]).read_bytes()).hexdigest()
        Path(str(built) + ".sha256").write_text(digest + "\n")

    def copy_extensions_to_source(self) -> None:
        super().copy_extensions_to_source()
        build_py = self.get_finalized_command("build_py")
        for ext in self.extensions:
            inplace, regular = self._get_inplace_equivalent(build_py, ext)
            if Path(regular + ".sha256").exists():
                self.copy_file(regular + ".sha256", inplace + ".sha256", level=self.verbose)

    def get_outputs(self) -> list[str]:
        built = super().get_outputs()
        return [*built, *(o + ".sha256" for o in built)]

    @staticmethod
    def _skipped(what: str, exc: Exception) -> None:
        print(f"wcdrive: {what} not built at install ({exc}); wcdrive compiles them on first "
              "use where a C compiler is there, else runs the slower Python paths "
              "(apt-get install gcc python3-dev, then reinstall)")

    def get_export_symbols(self, ext: Extension) -> list[str]:
        # the plant's kernel and ray cast are plain C: no PyInit_ to export
        plain = ext.name.endswith(("_chair_kernel", "_raycast"))
        return [] if plain else super().get_export_symbols(ext)


class BuildPyWithPth(build_py):
    """Also puts the .pth hook at the top of the wheel (site-packages)."""

    def run(self) -> None:
        super().run()
        self.copy_file(str(ROOT / PTH), str(Path(self.build_lib) / PTH))

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        return [*super().get_outputs(include_bytecode), str(Path(self.build_lib) / PTH)]


class EditableWheelWithPth(editable_wheel):
    """Editable installs get the same .pth hook (the finder maps the rest)."""

    def _select_strategy(self, name, tag, build_lib):  # type: ignore[no-untyped-def]
        strategy = super()._select_strategy(name, tag, build_lib)

        class WithPth:
            def __call__(self, wheel, files, mapping):  # type: ignore[no-untyped-def]
                strategy(wheel, files, mapping)
                wheel.writestr(PTH, (ROOT / PTH).read_bytes())

            def __enter__(self):  # type: ignore[no-untyped-def]
                strategy.__enter__()
                return self

            def __exit__(self, *exc):  # type: ignore[no-untyped-def]
                return strategy.__exit__(*exc)

        return WithPth()


setup(
    packages=[*python_packages("wcdrive", "wcdrive"), *python_packages("hil", "wcdrive.hil"),
              *DATA],
    package_dir={"wcdrive": "wcdrive", "wcdrive.hil": "hil", **DATA},
    package_data={"wcdrive": ["py.typed", "sim/scenarios/*.toml", "sim/scenarios/worlds/*",
                              "eddie/scenarios/*.toml", "plant/csrc/*.c",
                              "avr/csrc/*.c", "firmware/csrc/*.c", "boards/simavr/csrc/*.c"],
                  **{name: DATA_FILES for name in DATA}},
    py_modules=["_wcdrive_serial_urls"],
    ext_modules=NATIVE,
    cmdclass={"build_py": BuildPyWithPth, "editable_wheel": EditableWheelWithPth,
              "build_ext": OptionalBuildExt},
)
