"""Packaging details that pyproject.toml cannot say.

- ``hil/`` (the verification harness) ships inside the wheel as ``wcdrive.hil``;
  ``firmware/`` and ``protocol/`` ship as package data under ``wcdrive._data``, so a
  wheel installed anywhere can build the firmware and load the spec.
- ``wcdrive-serial-urls.pth`` goes to site-packages beside ``_wcdrive_serial_urls.py``,
  for wheels and editable installs alike: pyserial then finds ``wcsim://``,
  ``wcavr://`` and ``wccan://`` without importing wcdrive first.
"""

from __future__ import annotations

from pathlib import Path

from setuptools import setup
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
    package_data={"wcdrive": ["py.typed", "sim/scenarios/*.toml", "eddie/scenarios/*.toml", "plant/csrc/*.c",
                              "avr/csrc/*.c", "firmware/csrc/*.c", "boards/simavr/csrc/*.c"],
                  **{name: DATA_FILES for name in DATA}},
    py_modules=["_wcdrive_serial_urls"],
    cmdclass={"build_py": BuildPyWithPth, "editable_wheel": EditableWheelWithPth},
)
