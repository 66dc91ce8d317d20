"""ROS 2 Jazzy's message types as cyclonedds IDL classes, generated from the message
definitions in rosbags' type store; never written by hand.

``idl_class("geometry_msgs/msg/TwistStamped")`` is a ``cyclonedds.idl.IdlStruct``
dataclass named ``geometry_msgs::msg::dds_::TwistStamped_`` (the name a ROS 2 RMW
gives the type on the wire), whose fields are the message's, in order, with the
IDL type of each: ROS ``byte`` and ``char`` are ``uint8`` (octet), ``string`` an
unbounded (or bounded) string, ``T[N]`` an array, ``T[]`` and ``T[<=N]`` sequences.
Structs are final (the IDL default, as rosidl generates them), so their plain CDR
(XCDR1) is what a ROS 2 publisher sends. ``type_hash(name)`` is the RIHS01 hash ROS 2
Jazzy puts in the endpoint's USER_DATA, computed by the same type store.

``build(name, value)`` turns a dict in the message's field layout (nested dicts,
lists) into an instance; missing fields take their zero value. ``to_dict`` is the
inverse, for readers.
"""

from __future__ import annotations

import keyword
from functools import cache
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct, types
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import Nodetype

#: ROS 2 primitive -> the cyclonedds IDL type (rosidl's mapping).
_PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": types.uint8, "char": types.uint8,
    "int8": types.int8, "uint8": types.uint8, "int16": types.int16, "uint16": types.uint16,
    "int32": types.int32, "uint32": types.uint32, "int64": types.int64, "uint64": types.uint64,
    "float32": types.float32, "float64": types.float64,
}
#: cyclonedds' generic IDL types (typed loosely: mypy does not see them as generic).
_STR: Any = types.bounded_str
_ARRAY: Any = types.array
_SEQUENCE: Any = types.sequence
_ZERO: dict[str, Any] = {"bool": False, "float32": 0.0, "float64": 0.0, "string": ""}


@cache
def store() -> Any:
    """rosbags' type store for ROS 2 Jazzy."""
    return get_typestore(Stores.ROS2_JAZZY)


def dds_name(name: str) -> str:
    """``pkg/msg/Msg`` -> ``pkg::msg::dds_::Msg_``, the type's name on the wire."""
    package, kind, message = name.split("/")
    return f"{package}::{kind}::dds_::{message}_"


def type_hash(name: str) -> str:
    """The RIHS01 hash of ``name`` (``pkg/msg/Msg``) in ROS 2 Jazzy."""
    return str(store().hash_rihs01(name))


def _fields(name: str) -> list[tuple[str, Any]]:
    if name not in store().fielddefs:
        raise KeyError(f"{name} is not a ROS 2 Jazzy message in rosbags' type store")
    return list(store().fielddefs[name][1])


def _python_name(field: str) -> str:
    return field + "_" if keyword.iskeyword(field) else field


def _idl_type(desc: tuple[Any, Any]) -> Any:
    kind, rest = desc
    if kind == Nodetype.BASE:
        base, bound = rest
        if base == "string":
            return _STR[bound] if bound else str
        if base == "wstring":
            raise NotImplementedError("wstring fields are not supported")
        return _PRIMITIVES[base]
    if kind == Nodetype.NAME:
        return idl_class(rest)
    inner, count = rest
    if kind == Nodetype.ARRAY:
        return _ARRAY[_idl_type(inner), count]
    return _SEQUENCE[_idl_type(inner), count] if count else _SEQUENCE[_idl_type(inner)]


@cache
def idl_class(name: str) -> type[IdlStruct]:
    """The IDL class of the ROS 2 message ``name`` (``pkg/msg/Msg``), made once."""
    fields = {_python_name(f): _idl_type(desc) for f, desc in _fields(name)}
    return make_idl_struct(name.rsplit("/", 1)[1], dds_name(name), fields)


def _zero(desc: tuple[Any, Any]) -> Any:
    kind, rest = desc
    if kind == Nodetype.BASE:
        return _ZERO.get(rest[0], 0)
    if kind == Nodetype.NAME:
        return build(rest, {})
    inner, count = rest
    return [_zero(inner) for _ in range(count)] if kind == Nodetype.ARRAY else []


def _value(desc: tuple[Any, Any], value: Any) -> Any:
    kind, rest = desc
    if kind == Nodetype.BASE:
        return value
    if kind == Nodetype.NAME:
        return value if isinstance(value, IdlStruct) else build(rest, value)
    inner, _ = rest
    return [_value(inner, v) for v in value]


def build(name: str, value: dict[str, Any]) -> Any:
    """An instance of ``idl_class(name)`` from a dict in the message's layout; fields
    left out are zero (a KeyError names a field the message does not have)."""
    fields = _fields(name)
    unknown = set(value) - {f for f, _ in fields}
    if unknown:
        raise KeyError(f"{name} has no field {sorted(unknown)}")
    kwargs = {_python_name(f): _value(desc, value[f]) if f in value else _zero(desc) for f, desc in fields}
    return idl_class(name)(**kwargs)


def to_dict(name: str, message: Any) -> dict[str, Any]:
    """A received ``idl_class(name)`` instance as a dict in the message's layout."""
    out: dict[str, Any] = {}
    for field, (kind, rest) in _fields(name):
        value = getattr(message, _python_name(field))
        if kind == Nodetype.NAME:
            value = to_dict(rest, value)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and rest[0][0] == Nodetype.NAME:
            value = [to_dict(rest[0][1], v) for v in value]
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            value = list(value)
        out[field] = value
    return out
