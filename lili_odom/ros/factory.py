"""A :class:`lili_odom.messages.MessageFactory` for rclpy message classes.

rclpy's generated classes check field types strictly (``float`` for ``double``, ``int`` for
integers, ``array.array`` for numeric sequences, numpy arrays of the exact dtype for fixed
arrays); :class:`RclpyFactory` converts plain Python / numpy values accordingly.
"""
from __future__ import annotations

import array
import importlib
import re
from functools import lru_cache
from typing import Any

import numpy as np

__all__ = ["RclpyFactory", "message_class", "MessageTypeError"]


class MessageTypeError(LookupError):
    """A ROS message type has no importable Python class in this environment."""


# rosidl field type -> (numpy dtype, array.array typecode)
_NUMERIC = {
    "boolean": (np.bool_, None), "octet": (np.uint8, "B"), "uint8": (np.uint8, "B"),
    "char": (np.uint8, "B"), "byte": (np.uint8, "B"),
    "int8": (np.int8, "b"), "int16": (np.int16, "h"), "uint16": (np.uint16, "H"),
    "int32": (np.int32, "i"), "uint32": (np.uint32, "I"), "int64": (np.int64, "q"),
    "uint64": (np.uint64, "Q"), "float": (np.float32, "f"), "double": (np.float64, "d"),
}
_FLOATS = {"float", "double"}
_INTS = {"octet", "uint8", "char", "byte", "int8", "int16", "uint16", "int32", "uint32",
         "int64", "uint64"}
_SEQ = re.compile(r"^sequence<([\w/]+)(?:, ?\d+)?>$")
_ARR = re.compile(r"^([\w/]+)\[(\d+)\]$")


@lru_cache(maxsize=None)
def message_class(typename: str) -> type:
    """``pkg/msg/Name`` (or ``pkg/Name``) -> the rclpy message class.

    Raises:
        MessageTypeError: the package is not installed (e.g. ``tf2_msgs`` in the pip stack).
    """
    parts = typename.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise MessageTypeError(f"malformed message type name {typename!r}")
    pkg, sub, name = parts
    try:
        module = importlib.import_module(f"{pkg}.{sub}")
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise MessageTypeError(f"message type {typename} is not available "
                               f"(Python package {pkg!r} not installed)") from None


class RclpyFactory:
    """Builds rclpy messages by type name (``pkg/msg/Name``)."""

    def new(self, typename: str, **fields: Any) -> Any:
        cls = message_class(typename)
        types = cls.get_fields_and_field_types()
        msg = cls()
        for name, value in fields.items():
            if name not in types:
                raise TypeError(f"{typename} has no field {name!r}")
            setattr(msg, name, _convert(value, types[name]))
        return msg

    @staticmethod
    def serialize(msg: Any) -> bytes:
        from rclpy.serialization import serialize_message

        return serialize_message(msg)


def _convert(value: Any, ftype: str) -> Any:
    if ftype in _FLOATS:
        return float(value)
    if ftype in _INTS:
        return int(value)
    if ftype == "boolean":
        return bool(value)
    if ftype == "string" or ftype.startswith("string<"):
        return str(value)
    m = _SEQ.match(ftype)
    if m:
        elem = m.group(1)
        if elem in _NUMERIC and _NUMERIC[elem][1] is not None:
            dtype, code = _NUMERIC[elem]
            out = array.array(code)
            if isinstance(value, (bytes, bytearray, memoryview)) and code == "B":
                out.frombytes(bytes(value))
            else:
                out.frombytes(np.ascontiguousarray(np.asarray(value, dtype=dtype)
                                                   .reshape(-1)).tobytes())
            return out
        return list(value)
    m = _ARR.match(ftype)
    if m and m.group(1) in _NUMERIC:
        return np.asarray(value, dtype=_NUMERIC[m.group(1)][0]).reshape(-1)
    return value
