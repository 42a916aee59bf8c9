"""A :class:`lili_odom.messages.MessageFactory` for ``rosbags`` message classes.

rosbags messages are dataclasses without defaults and want numpy arrays for numeric arrays and
sequences; :class:`RosbagsFactory` fills every field that is not given from the type's field
definitions (zeros, empty strings and sequences, identity quaternions) and converts numeric
arrays (including ``bytes`` for ``uint8[]``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ["RosbagsFactory", "jazzy_typestore"]

# rosbags field descriptor node kinds (rosbags.interfaces.Nodetype values)
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4

_NUMERIC = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8,
    "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
    "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64,
}


def jazzy_typestore() -> Typestore:
    """The ROS 2 Jazzy type store shipped with rosbags."""
    return get_typestore(Stores.ROS2_JAZZY)


class RosbagsFactory:
    """Builds rosbags messages by type name (``pkg/msg/Name``)."""

    def __init__(self, typestore: Typestore | None = None) -> None:
        self.typestore = typestore or jazzy_typestore()

    def serialize(self, msg: Any) -> bytes:
        """CDR bytes (little endian, with the encapsulation header), as rosbag2 stores them."""
        return bytes(self.typestore.serialize_cdr(msg, msg.__msgtype__))

    def new(self, typename: str, **fields: Any) -> Any:
        try:
            cls = self.typestore.types[typename]
            _, defs = self.typestore.fielddefs[typename]
        except KeyError:
            raise KeyError(f"message type {typename!r} is not in the type store") from None
        names = {name for name, _ in defs}
        unknown = set(fields) - names
        if unknown:
            raise TypeError(f"{typename} has no field(s) {sorted(unknown)}")
        values = {}
        for name, desc in defs:
            if name in fields:
                values[name] = self._convert(fields[name], desc)
            else:
                values[name] = self._default(desc, typename, name)
        return cls(**values)

    # -- helpers -------------------------------------------------------------------------

    @staticmethod
    def _numeric_element(desc: Any) -> Any:
        """numpy dtype when ``desc`` is an array/sequence of a numeric base type, else None."""
        kind, rest = desc
        if kind not in (_ARRAY, _SEQUENCE):
            return None
        (elem_kind, elem), _ = rest
        if elem_kind != _BASE:
            return None
        return _NUMERIC.get(elem[0])

    def _convert(self, value: Any, desc: Any) -> Any:
        dtype = self._numeric_element(desc)
        if dtype is None:
            if desc[0] in (_ARRAY, _SEQUENCE):
                return list(value)
            return value
        if isinstance(value, (bytes, bytearray, memoryview)) and np.dtype(dtype).itemsize == 1:
            return np.frombuffer(bytes(value), dtype=dtype)
        return np.ascontiguousarray(np.asarray(value, dtype=dtype).reshape(-1))

    def _default(self, desc: Any, typename: str, field: str) -> Any:
        kind, rest = desc
        if kind == _BASE:
            base = rest[0]
            if base == "string":
                return ""
            if base == "bool":
                return False
            if base.startswith("float"):
                # geometry_msgs/Quaternion defaults to identity (w = 1), as in ROS.
                return 1.0 if (typename == "geometry_msgs/msg/Quaternion" and field == "w") else 0.0
            return 0
        if kind == _NAME:
            return self.new(rest)
        if kind == _ARRAY:
            elem, size = rest
            dtype = self._numeric_element(desc)
            if dtype is not None:
                return np.zeros(size, dtype=dtype)
            return [self._default(elem, typename, field) for _ in range(size)]
        if kind == _SEQUENCE:
            dtype = self._numeric_element(desc)
            return np.zeros(0, dtype=dtype) if dtype is not None else []
        raise TypeError(f"unsupported field descriptor {desc!r} in {typename}.{field}")
