"""The check that a ctypes ``Structure`` lays a C struct out as the C compiler does.

``check_layout(Mirror, lib, "chair_layout")`` calls the C library's exported
``chair_layout()`` for the struct's layout as compiled (``c_layout``), takes the mirror's
from ctypes (``mirror_layout``) and raises ``StructLayoutError`` at the first field that
differs: a field missing from either side, another field in its place, or the same
field at another offset, of another size or of another kind; then a whole struct of
another size. The message names the mirror, the C struct and that field. A C layout
that leaves a gap no alignment explains (a field left out of its table) is refused too.

Each C library exports, per mirrored struct, a function returning a pointer to a
``wc_layout`` (``LayoutRecord``)::

    typedef struct { const char *name; size_t offset, size; char kind; } wc_field;
    typedef struct { size_t layout_size, field_size; const char *name; size_t size, count;
                     const wc_field *fields; } wc_layout;

filled by the compiler: ``offsetof``, ``sizeof``, and for the kind ``_Generic`` on the
field (on an array's first element): ``d`` double, ``f`` float, ``i``/``I`` 32-bit
signed/unsigned, ``q``/``Q`` 64-bit, ``p`` anything else (the pointers). The first two
sizes let the records be checked before they are read.

Why: a ctypes mirror is written by hand; a field added, dropped or retyped on one side
only does not fail, it makes the kernel read and write the wrong bytes (a parameter
read as another, a state written past the struct). Names and offsets from the compiler
turn that into an error at load, naming the field. Kinds catch what sizes cannot (a
double where C has an int64). The C struct's table is written by hand too, but every
name in it is checked by the compiler, and a field left out of it leaves a gap (or a
mismatch with the mirror) that this check reports.
"""

from __future__ import annotations

import _ctypes
import ctypes
from dataclasses import dataclass
from typing import Any

from wcdrive.errors import WcdriveError


class StructLayoutError(WcdriveError, RuntimeError):
    """A ctypes mirror does not lay its C struct out as the C compiler does (or the C
    library's layout table is not whole); the message names the struct and the field."""


@dataclass(frozen=True)
class FieldLayout:
    """One field: its name, its offset and size in bytes, its kind (module docstring)."""

    name: str
    offset: int
    size: int
    kind: str

    def describe(self) -> str:
        """``name at offset 8, 4 bytes of int32``, for the error messages."""
        kind = _KIND_NAMES.get(self.kind, self.kind)
        return f"{self.name} at offset {self.offset}, {self.size} bytes of {kind}"


@dataclass(frozen=True)
class StructLayout:
    """A struct's name, its size in bytes and its fields by offset."""

    name: str
    size: int
    fields: tuple[FieldLayout, ...]


class FieldRecord(ctypes.Structure):
    """``wc_field`` of the C libraries (module docstring)."""

    _fields_ = [("name", ctypes.c_char_p), ("offset", ctypes.c_size_t), ("size", ctypes.c_size_t),
                ("kind", ctypes.c_char)]


class LayoutRecord(ctypes.Structure):
    """``wc_layout`` of the C libraries (module docstring)."""

    _fields_ = [("layout_size", ctypes.c_size_t), ("field_size", ctypes.c_size_t),
                ("name", ctypes.c_char_p), ("size", ctypes.c_size_t), ("count", ctypes.c_size_t),
                ("fields", ctypes.POINTER(FieldRecord))]


_KIND_NAMES = {"d": "double", "f": "float", "i": "int32", "I": "uint32", "q": "int64", "Q": "uint64",
               "p": "pointer", "?": "a type the check does not know"}
#: A kind's alignment in bytes (``p``: a pointer's).
_ALIGNMENT = {"d": 8, "f": 4, "i": 4, "I": 4, "q": 8, "Q": 8, "p": ctypes.sizeof(ctypes.c_void_p)}


def c_layout(lib: ctypes.CDLL, symbol: str) -> StructLayout:
    """The layout that ``lib``'s ``symbol()`` gives (a ``wc_layout *``), its fields
    sorted by offset. Raises ``StructLayoutError`` when the records are not the size
    ``FieldRecord`` and ``LayoutRecord`` expect, or the table leaves a field out."""
    function = getattr(lib, symbol)
    function.argtypes = []
    function.restype = ctypes.POINTER(LayoutRecord)
    record = function()
    if not record:
        raise StructLayoutError(f"{symbol}() gave no layout")
    head = ctypes.cast(record, ctypes.POINTER(ctypes.c_size_t * 2)).contents
    if (head[0], head[1]) != (ctypes.sizeof(LayoutRecord), ctypes.sizeof(FieldRecord)):
        raise StructLayoutError(f"{symbol}(): its wc_layout and wc_field are {head[0]} and {head[1]} bytes, "
                                f"LayoutRecord and FieldRecord {ctypes.sizeof(LayoutRecord)} and "
                                f"{ctypes.sizeof(FieldRecord)}")
    layout = record.contents
    fields = [FieldLayout(f.name.decode(), f.offset, f.size, f.kind.decode())
              for f in layout.fields[:layout.count]]
    out = StructLayout(layout.name.decode(), layout.size, tuple(sorted(fields, key=lambda f: f.offset)))
    _check_whole(out, symbol)
    return out


def mirror_layout(mirror: type[ctypes.Structure]) -> StructLayout:
    """The layout ctypes gives ``mirror``, in the order of its ``_fields_``."""
    fields = []
    for entry in mirror._fields_:
        name, ctype = entry[0], entry[1]
        descriptor = getattr(mirror, name)
        fields.append(FieldLayout(name, descriptor.offset, descriptor.size, _kind(ctype)))
    return StructLayout(mirror.__name__, ctypes.sizeof(mirror), tuple(fields))


def check_layout(mirror: type[ctypes.Structure], lib: ctypes.CDLL, symbol: str) -> None:
    """Holds ``mirror`` to the C layout ``lib``'s ``symbol()`` gives (module docstring);
    raises ``StructLayoutError`` at the first field that differs."""
    compare_layouts(mirror_layout(mirror), c_layout(lib, symbol))


def compare_layouts(mirror: StructLayout, c: StructLayout) -> None:
    """Raises ``StructLayoutError`` at the first field where ``mirror`` is not ``c``, or
    when the two structs' sizes differ."""
    where = f"{mirror.name} does not mirror {c.name}"
    mirrored = {f.name for f in mirror.fields}
    in_c = {f.name for f in c.fields}
    for ours, theirs in zip(mirror.fields, c.fields, strict=False):
        if ours == theirs:
            continue
        if ours.name == theirs.name:
            raise StructLayoutError(f"{where}: field {ours.name!r} differs: {c.name} has "
                                    f"{theirs.describe()}; {mirror.name} has {ours.describe()}")
        if theirs.name not in mirrored:
            raise StructLayoutError(f"{where}: field {theirs.name!r} is missing from {mirror.name} "
                                    f"({c.name} has {theirs.describe()})")
        if ours.name not in in_c:
            raise StructLayoutError(f"{where}: field {ours.name!r} is not in {c.name} "
                                    f"({mirror.name} has {ours.describe()})")
        raise StructLayoutError(f"{where}: field {theirs.name!r}: {c.name} has {theirs.describe()}; "
                                f"{mirror.name} has {ours.describe()} in its place")
    n = len(c.fields)
    if len(mirror.fields) < n:
        missing = c.fields[len(mirror.fields)]
        raise StructLayoutError(f"{where}: field {missing.name!r} is missing from {mirror.name} "
                                f"({c.name} has {missing.describe()})")
    if len(mirror.fields) > n:
        extra = mirror.fields[n]
        raise StructLayoutError(f"{where}: field {extra.name!r} is not in {c.name} "
                                f"({mirror.name} has {extra.describe()})")
    if mirror.size != c.size:
        raise StructLayoutError(f"{where}: {mirror.name} is {mirror.size} bytes, {c.name} {c.size}")


def _check_whole(layout: StructLayout, symbol: str) -> None:
    """A field left out of a C table leaves a gap at least its alignment wide (padding
    is narrower than the next field's alignment, the struct's tail narrower than the
    widest's)."""
    end = 0
    widest = 1
    for f in layout.fields:
        align = _ALIGNMENT.get(f.kind, 1)
        widest = max(widest, align)
        if f.offset < end or f.offset - end >= align:
            raise StructLayoutError(f"{symbol}(): {layout.name}'s table has {f.describe()} after "
                                    f"byte {end}: a field is left out of the table, or overlaps")
        end = f.offset + f.size
    if layout.size < end or layout.size - end >= widest:
        raise StructLayoutError(f"{symbol}(): {layout.name}'s table ends at byte {end} of its "
                                f"{layout.size}: a field is left out of the table")


def _kind(ctype: Any) -> str:
    """The kind (module docstring) of a ctypes type, an array's its elements'."""
    while issubclass(ctype, ctypes.Array):
        ctype = ctype._type_
    if issubclass(ctype, (_ctypes._Pointer, _ctypes.CFuncPtr, ctypes.c_void_p, ctypes.c_char_p,
                          ctypes.c_wchar_p)):
        return "p"
    if issubclass(ctype, _ctypes._SimpleCData):
        code, size = ctype._type_, ctypes.sizeof(ctype)
        if code in "df":
            return str(code)
        if code in "bhilq":
            return {4: "i", 8: "q"}.get(size, "?")
        if code in "BHILQ":
            return {4: "I", 8: "Q"}.get(size, "?")
    return "?"
