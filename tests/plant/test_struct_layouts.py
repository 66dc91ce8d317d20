"""The ctypes mirrors of the C kernels' structs (``ChairStruct``; ``GridStruct``,
``TurnStruct``, ``JobStruct``) lay them out as the C compiler did: every field's name,
offset, size and kind, and the whole struct's size, as the libraries export them. A
mirror with a field dropped, retyped, resized, moved or added is refused with an error
naming the struct and the field, and loading a kernel refuses it too; a C table that
leaves a field out, or whose records are not the size Python reads, is refused."""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest

from wcdrive.plant import chair_kernel, raycast
from wcdrive.plant.chair_kernel import ChairStruct, load_kernel
from wcdrive.plant.raycast import GridStruct, JobStruct, TurnStruct, load_raycast
from wcdrive.plant.struct_layout import (
    FieldRecord,
    LayoutRecord,
    StructLayoutError,
    c_layout,
    check_layout,
    mirror_layout,
)

#: (mirror, the C struct, how its library is had, the function that gives its layout)
MIRRORS: list[tuple[type[ctypes.Structure], str, Callable[[], ctypes.CDLL | None], str]] = [
    (ChairStruct, "chair_t", load_kernel, "chair_layout"),
    (GridStruct, "rc_grid", load_raycast, "rc_grid_layout"),
    (TurnStruct, "rc_lidar", load_raycast, "rc_lidar_layout"),
    (JobStruct, "rc_job", load_raycast, "rc_job_layout"),
]
IDS = [m[0].__name__ for m in MIRRORS]


def _lib(load: Callable[[], ctypes.CDLL | None]) -> ctypes.CDLL:
    lib = load()
    assert lib is not None, "the C helper could not be had"
    return lib


def _mirror(name: str, fields: list[tuple[Any, ...]]) -> type[ctypes.Structure]:
    """A ctypes Structure ``name`` with these ``_fields_``."""
    return type(name, (ctypes.Structure,), {"_fields_": fields})


def _fields(mirror: type[ctypes.Structure]) -> list[tuple[Any, ...]]:
    return [tuple(f) for f in mirror._fields_]


def _moved(mirror: type[ctypes.Structure], field: str, to: int) -> list[tuple[Any, ...]]:
    """The mirror's fields with ``field`` moved to index ``to``."""
    fields = _fields(mirror)
    moved = next(f for f in fields if f[0] == field)
    rest = [f for f in fields if f[0] != field]
    return [*rest[:to], moved, *rest[to:]]


def _retyped(mirror: type[ctypes.Structure], field: str, ctype: Any) -> list[tuple[Any, ...]]:
    return [(n, ctype) if n == field else (n, t) for n, t in _fields(mirror)]


@pytest.mark.parametrize(("mirror", "c_name", "load", "symbol"), MIRRORS, ids=IDS)
def test_each_mirror_lays_its_c_struct_out_as_the_compiler_did(mirror, c_name, load, symbol) -> None:
    lib = _lib(load)
    check_layout(mirror, lib, symbol)
    c, ours = c_layout(lib, symbol), mirror_layout(mirror)
    assert c.name == c_name and ours.name == mirror.__name__
    assert c.size == ours.size == ctypes.sizeof(mirror)
    assert c.fields == ours.fields
    assert [f.name for f in c.fields] == [f[0] for f in mirror._fields_]      # every field, in order


def test_the_kinds_are_the_c_types() -> None:
    kinds = {f.name: f.kind for f in c_layout(_lib(load_kernel), "chair_layout").fields}
    assert (kinds["half_base"], kinds["mu"], kinds["space"], kinds["locked"], kinds["n_ramps"]) == \
        ("d", "d", "p", "i", "i")
    kinds = {f.name: f.kind for f in c_layout(_lib(load_raycast), "rc_lidar_layout").fields}
    assert (kinds["intensity"], kinds["device"], kinds["samples"]) == ("f", "p", "i")


@pytest.mark.parametrize(("mirror", "fields", "c_name", "field"), [
    # a field dropped: the one after it sits where it was
    (ChairStruct, [f for f in _fields(ChairStruct) if f[0] != "r"], "chair_t", "r"),
    (GridStruct, [f for f in _fields(GridStruct) if f[0] != "n_circ"], "rc_grid", "n_circ"),
    # the last field dropped (nothing after it moves)
    (JobStruct, _fields(JobStruct)[:-1], "rc_job", "log_t0"),
    (ChairStruct, _fields(ChairStruct)[:-1], "chair_t", "brake_engaged"),
    # a type changed: another size, or the same size and another kind
    (GridStruct, _retyped(GridStruct, "n_seg", ctypes.c_double), "rc_grid", "n_seg"),
    (TurnStruct, _retyped(TurnStruct, "intensity", ctypes.c_int32), "rc_lidar", "intensity"),
    (GridStruct, _retyped(GridStruct, "scale", ctypes.c_int64), "rc_grid", "scale"),
    (ChairStruct, _retyped(ChairStruct, "time", ctypes.c_void_p), "chair_t", "time"),
    # an array of another length
    (ChairStruct, _retyped(ChairStruct, "mu", ctypes.c_double * 3), "chair_t", "mu"),
    # two fields swapped
    (TurnStruct, _moved(TurnStruct, "mount_y", 6), "rc_lidar", "mount_x"),
    # a field C does not have
    (JobStruct, [*_fields(JobStruct), ("spare", ctypes.c_int32)], "rc_job", "spare"),
    (GridStruct, [*_fields(GridStruct)[:2], ("extra", ctypes.c_void_p), *_fields(GridStruct)[2:]],
     "rc_grid", "extra"),
], ids=["dropped", "dropped-int", "last-dropped", "last-int-dropped", "resized", "int-for-float",
        "int64-for-double", "pointer-for-double", "array-length", "swapped", "added-at-end", "added"])
def test_a_wrong_mirror_is_refused_naming_the_struct_and_the_field(mirror, fields, c_name, field) -> None:
    symbol, load = {m[1]: (m[3], m[2]) for m in MIRRORS}[c_name]
    wrong = _mirror(f"Wrong{mirror.__name__}", fields)
    with pytest.raises(StructLayoutError, match=rf"Wrong{mirror.__name__}.*{c_name}") as caught:
        check_layout(wrong, _lib(load), symbol)
    assert f"field {field!r}" in str(caught.value), str(caught.value)


def test_the_messages_say_what_differs() -> None:
    lib = _lib(load_raycast)
    wrong = _mirror("BadGrid", _retyped(GridStruct, "n_seg", ctypes.c_double))
    with pytest.raises(StructLayoutError) as caught:
        check_layout(wrong, lib, "rc_grid_layout")
    assert str(caught.value) == ("BadGrid does not mirror rc_grid: field 'n_seg' differs: rc_grid has "
                                 "n_seg at offset 8, 4 bytes of int32; BadGrid has n_seg at offset 8, "
                                 "8 bytes of double")
    wrong = _mirror("BadGrid", [f for f in _fields(GridStruct) if f[0] != "circ"])
    with pytest.raises(StructLayoutError, match="field 'circ' is missing from BadGrid"):
        check_layout(wrong, lib, "rc_grid_layout")


def test_loading_a_kernel_checks_its_mirrors(monkeypatch: pytest.MonkeyPatch) -> None:
    """``load_kernel`` and ``load_raycast`` hold their mirrors to C before they bind a
    function: a wrong one is an error, not a kernel that writes the wrong bytes."""
    _lib(load_kernel)
    _lib(load_raycast)
    monkeypatch.setattr(chair_kernel, "_kernel", None)
    monkeypatch.setattr(chair_kernel, "ChairStruct", _mirror("ChairStruct", _fields(ChairStruct)[1:]))
    with pytest.raises(StructLayoutError, match="field 'half_base' is missing from ChairStruct"):
        chair_kernel.load_kernel()
    monkeypatch.setattr(raycast, "_lib", None)
    wrong = _mirror("TurnStruct", _retyped(TurnStruct, "beams", ctypes.c_double))
    monkeypatch.setattr(raycast, "TurnStruct", wrong)
    with pytest.raises(StructLayoutError, match="TurnStruct does not mirror rc_lidar: field 'beams'"):
        raycast.load_raycast()


class _Exported:
    """A C function that returns a ``wc_layout *``, as ctypes calls one."""

    def __init__(self, record: LayoutRecord, fields: ctypes.Array[FieldRecord]) -> None:
        self.record, self.fields = record, fields               # the fields kept while it is
        self.argtypes, self.restype = None, None

    def __call__(self) -> Any:
        return ctypes.pointer(self.record)


def _fake_lib(fields: list[tuple[str, int, int, str]], size: int, field_size: int | None = None) -> Any:
    """A library whose ``layout()`` gives a struct ``fake_t`` of ``size`` bytes with these
    fields (name, offset, size, kind); its records ``field_size`` bytes as it says."""
    records = (FieldRecord * len(fields))(*(FieldRecord(n.encode(), o, s, k.encode())
                                            for n, o, s, k in fields))
    layout = LayoutRecord(ctypes.sizeof(LayoutRecord), field_size or ctypes.sizeof(FieldRecord), b"fake_t",
                          size, len(fields), ctypes.cast(records, ctypes.POINTER(FieldRecord)))
    return SimpleNamespace(layout=_Exported(layout, records))


FAKE = [("a", 0, 8, "d"), ("b", 8, 4, "i"), ("c", 16, 8, "p"), ("d", 24, 4, "f")]


def test_a_c_table_that_leaves_a_field_out_is_refused() -> None:
    assert [f.name for f in c_layout(_fake_lib(FAKE, 32), "layout").fields] == ["a", "b", "c", "d"]
    # the padding after b (4 bytes before an 8-byte pointer) is no gap; 8 bytes after a is
    with pytest.raises(StructLayoutError, match=r"fake_t's table has c at offset 16.*after byte 8"):
        c_layout(_fake_lib([FAKE[0], FAKE[2], FAKE[3]], 32), "layout")
    # nor is a tail narrower than the widest alignment; a whole field's worth is
    assert len(c_layout(_fake_lib(FAKE[:2], 16), "layout").fields) == 2
    with pytest.raises(StructLayoutError, match="fake_t's table ends at byte 24 of its 32"):
        c_layout(_fake_lib(FAKE[:3], 32), "layout")
    with pytest.raises(StructLayoutError, match="overlaps"):
        c_layout(_fake_lib([FAKE[0], ("b", 4, 4, "i"), *FAKE[2:]], 32), "layout")


def test_a_c_table_is_read_only_when_its_records_are_the_size_python_reads() -> None:
    with pytest.raises(StructLayoutError, match=r"its wc_layout and wc_field are \d+ and 24 bytes"):
        c_layout(_fake_lib(FAKE, 32, field_size=24), "layout")
