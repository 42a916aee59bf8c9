"""Dataclass configs <-> flat ROS parameter names (pure Python, no rclpy).

A nested dataclass config maps onto dotted parameter names the same way a ROS parameters YAML
file nests (``lili_odom: ros__parameters: scan_matcher: max_range: 80.0`` is the parameter
``scan_matcher.max_range``), so ``--ros-args --params-file config/lili_odom.yaml`` and the
offline loader read the same file.
"""
from __future__ import annotations

import dataclasses
import typing
from typing import Any, Mapping

import numpy as np

__all__ = ["flatten_config", "build_config", "coerce_like"]


def flatten_config(config: Any, prefix: str = "") -> dict[str, Any]:
    """Dataclass instance -> ``{dotted name: value}`` with ROS-compatible values.

    numpy arrays and tuples become lists (matrices flattened row-major); None stays None.
    """
    out: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out.update(flatten_config(value, name + "."))
        elif isinstance(value, np.ndarray):
            out[name] = [v.item() for v in value.reshape(-1)]
        elif isinstance(value, (tuple, list)):
            out[name] = [v.item() if isinstance(v, np.generic) else v for v in value]
        elif isinstance(value, np.generic):
            out[name] = value.item()
        else:
            out[name] = value
    return out


def coerce_like(value: Any, default: Any, name: str = "") -> Any:
    """Convert a parameter value to the type of the field's ``default``.

    Raises:
        ValueError: the value cannot be converted (message names the parameter).
    """
    if value is None:
        return None
    try:
        if isinstance(default, bool):
            if isinstance(value, str):
                if value.lower() in ("true", "1", "yes"):
                    return True
                if value.lower() in ("false", "0", "no"):
                    return False
                raise ValueError(value)
            return bool(value)
        if isinstance(default, int) and not isinstance(default, bool):
            if isinstance(value, float) and not value.is_integer():
                raise ValueError(value)
            return int(value)
        if isinstance(default, float):
            return float(value)
        if isinstance(default, str):
            return str(value)
        if isinstance(default, np.ndarray):
            arr = np.asarray(value, dtype=default.dtype)
            return arr.reshape(default.shape) if arr.size == default.size else arr
        if isinstance(default, tuple):
            return tuple(value)
        if isinstance(default, list):
            return list(value)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name or '?'}: cannot use {value!r} "
                         f"(expected {type(default).__name__})") from None
    return value


def build_config(cls: type, values: Mapping[str, Any], prefix: str = "") -> Any:
    """Inverse of :func:`flatten_config`: a ``cls`` instance from ``{dotted name: value}``.

    Names missing from ``values`` keep the dataclass defaults; extra names are ignored.
    """
    default = cls()
    kwargs: dict[str, Any] = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        name = f"{prefix}{f.name}"
        current = getattr(default, f.name)
        sub_cls = type(current) if dataclasses.is_dataclass(current) else None
        if sub_cls is None and isinstance(hints.get(f.name), type) and dataclasses.is_dataclass(
                hints[f.name]):
            sub_cls = hints[f.name]
        if sub_cls is not None:
            kwargs[f.name] = build_config(sub_cls, values, name + ".")
        elif name in values:
            kwargs[f.name] = coerce_like(values[name], current, name)
    return cls(**kwargs)
