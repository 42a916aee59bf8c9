"""Door ``clouds``: PointCloud2 content into :func:`lili_odom.pointcloud2.parse_cloud`.

A case is a small valid cloud in one of several layouts (ouster-ros "original", plain x/y/z
float32 with or without a float time, float64 with integer nanoseconds, padded rows, either
byte order) with up to three mutations of its fields, datatypes, steps, sizes, payload, byte
order, coordinate values or per-point times. The parser must return a cloud whose points and
times are finite and whose counters add up, or raise ``CloudFormatError``.
"""
from __future__ import annotations

import array
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np

from lili_odom.fuzz.outcome import CLEAN, INVALID, NONFINITE, Outcome, from_exception

F32_MAX = float(np.finfo(np.float32).max)


# ------------------------------------------------------------------------------ valid clouds
def _layout(rng: np.random.Generator) -> tuple[str, list[tuple[str, int, str]], int, bool]:
    """(name, [(field, offset, numpy type)], point_step, big-endian)."""
    big = bool(rng.random() < 0.3)
    kind = int(rng.integers(5))
    if kind == 0:  # ouster-ros original
        return "ouster", [("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4"), ("intensity", 16, "f4"),
                          ("t", 20, "u4"), ("reflectivity", 24, "u2"), ("ring", 26, "u2"),
                          ("ambient", 28, "u2"), ("range", 32, "u4")], 48, big
    if kind == 1:
        return "xyz", [("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4")], 12, big
    if kind == 2:
        return "xyzit", [("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4"), ("intensity", 12, "f4"),
                         ("time", 16, "f4")], 20, big
    if kind == 3:
        return "xyz64_ns", [("x", 0, "f8"), ("y", 8, "f8"), ("z", 16, "f8"),
                            ("timestamp", 24, "u4")], 32, big
    return "xyz_i16_padded", [("z", 4, "f4"), ("x", 8, "f4"), ("y", 12, "f4"),
                              ("t", 16, "i4"), ("ring", 20, "u2")], 24, big


_DATATYPE = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


def valid_cloud(rng: np.random.Generator) -> tuple[SimpleNamespace, np.ndarray, str]:
    """(cloud message, structured records, description) of a small valid cloud."""
    name, fields, step, big = _layout(rng)
    organized = rng.random() < 0.4
    height = int(rng.integers(1, 5)) if organized else 1
    width = int(rng.integers(0, 60))
    n = height * width
    order = ">" if big else "<"
    dt = np.dtype({"names": [f for f, _, _ in fields],
                   "formats": [order + t for _, _, t in fields],
                   "offsets": [o for _, o, _ in fields], "itemsize": step})
    rec = np.zeros(n, dtype=dt)
    xyz = rng.uniform(-20, 20, (n, 3))
    for i, axis in enumerate("xyz"):
        rec[axis] = xyz[:, i]
    for f, _, t in fields:
        if f in ("t", "timestamp"):
            rec[f] = np.sort(rng.integers(0, 100_000_000, n)).astype(t)
        elif f == "time":
            rec[f] = np.linspace(0.0, 0.1, n)
        elif f == "range":
            rec[f] = (np.linalg.norm(xyz, axis=1) * 1000).astype(np.uint32)
        elif f not in "xyz":
            rec[f] = rng.integers(0, 100, n).astype(t)
    pad = int(rng.integers(0, 9)) if rng.random() < 0.2 else 0
    row_step = step * width + pad
    rows = np.zeros((height, row_step), np.uint8)
    if n:
        rows[:, : step * width] = rec.view(np.uint8).reshape(height, step * width)
    msg = SimpleNamespace(
        fields=[SimpleNamespace(name=f, offset=o, datatype=_DATATYPE[t], count=1)
                for f, o, t in fields],
        is_bigendian=big, point_step=step, row_step=row_step, height=height, width=width,
        data=rows.tobytes(), is_dense=False)
    return msg, rec, f"{name} {height}x{width} {'BE' if big else 'LE'} pad {pad}"


# ------------------------------------------------------------------------------ mutations
def _pick(rng: np.random.Generator, options: list) -> Any:
    return options[int(rng.integers(len(options)))]


_BAD_INTS = [0, -1, 1, 3, 7, 4.5, 48.0, "48", None, True, 1 << 20, 1 << 40, -(1 << 31), 1e300,
             float("nan"), float("inf"), np.int64(12), np.uint8(255), [4], object()]


def _mut_field(rng, msg, rec):
    fields = list(msg.fields)
    if not fields:
        msg.fields = None
        return "fields None"
    i = int(rng.integers(len(fields)))
    f = SimpleNamespace(**vars(fields[i]))
    what = int(rng.integers(10))
    if what == 0:
        del fields[i]
        msg.fields = fields
        return f"drop field {f.name}"
    if what == 1:
        attr = _pick(rng, ["offset", "datatype", "count", "name"])
        delattr(f, attr)
        fields[i] = f
        msg.fields = fields
        return f"field {getattr(f, 'name', '?')} without {attr}"
    if what == 2:
        f.datatype = _pick(rng, [0, 9, -1, 255, 2.5, "7", None, 7.0, 1, 2, 3, 4, 5, 6, 8])
        fields[i] = f
        msg.fields = fields
        return f"field {f.name} datatype {f.datatype!r}"
    if what == 3:
        f.offset = _pick(rng, _BAD_INTS + [msg.point_step if isinstance(msg.point_step, int) else 0])
        fields[i] = f
        msg.fields = fields
        return f"field {f.name} offset {f.offset!r}"
    if what == 4:
        f.count = _pick(rng, [0, -1, 2, 3, 1 << 30, 1.5, None, "1"])
        fields[i] = f
        msg.fields = fields
        return f"field {f.name} count {f.count!r}"
    if what == 5:
        f.name = _pick(rng, ["", "X", "t", "time", "timestamp", "range", None, 7, b"x", "x"])
        fields[i] = f
        msg.fields = fields
        return f"field {i} renamed {f.name!r}"
    if what == 6:
        fields.append(SimpleNamespace(**vars(fields[i])))
        msg.fields = fields
        return f"duplicate field {f.name}"
    if what == 7:
        fields[i] = _pick(rng, [(f.name, f.offset, f.datatype), (f.name, f.offset), (f.name,),
                                (f.name, f.offset, f.datatype, f.count, 0), f.name, None, 5,
                                {"name": f.name}])
        msg.fields = fields
        return f"field entry {fields[i]!r}"
    if what == 8:
        msg.fields = _pick(rng, [None, 5, "xyz", iter(fields), tuple(fields), {}, b"abc"])
        return f"fields {type(msg.fields).__name__}"
    for g in fields:  # every field at offset 0 (overlapping)
        g.offset = 0
    msg.fields = fields
    return "all fields at offset 0"


def _mut_sizes(rng, msg, rec):
    attr = _pick(rng, ["point_step", "row_step", "height", "width", "height", "width"])
    old = getattr(msg, attr)
    choice = int(rng.integers(4))
    if choice == 0 and isinstance(old, int):
        new = old + int(rng.integers(-5, 6))
    elif choice == 1 and attr in ("height", "width"):
        new = _pick(rng, [0, 1 << 13, 1 << 27, 1 << 31, 1 << 62, -1, msg.width, msg.height])
    else:
        new = _pick(rng, _BAD_INTS)
    setattr(msg, attr, new)
    return f"{attr} {old!r} -> {new!r}"


def _mut_data(rng, msg, rec):
    data = bytes(msg.data)
    what = int(rng.integers(9))
    if what == 0:
        k = int(rng.integers(0, len(data) + 1))
        msg.data = data[:k]
        return f"data truncated to {k}"
    if what == 1:
        msg.data = data + bytes(int(rng.integers(1, 64)))
        return "data extended"
    if what == 2:
        msg.data = _pick(rng, [None, "abc", 3.5, 17, object()])
        return f"data {type(msg.data).__name__}"
    if what == 3:
        msg.data = list(data) + ([300] if rng.random() < 0.5 else [-1])
        return "data list with out-of-byte value"
    if what == 4:
        msg.data = np.frombuffer(data, np.uint8).astype(
            _pick(rng, [np.float32, np.int16, np.int8, np.uint16, np.bool_]))
        return f"data numpy {msg.data.dtype}"
    if what == 5:
        arr = np.frombuffer(data + bytes(len(data) % 2), np.uint8)
        msg.data = arr.reshape(2, -1) if arr.size else arr
        msg.data = msg.data[:, ::2] if msg.data.ndim == 2 and rng.random() < 0.5 else msg.data
        return "data 2-D numpy / strided"
    if what == 6:
        msg.data = array.array(_pick(rng, ["B", "b", "f", "H"]), data[: len(data) // 4 * 4])
        return f"data array.array({msg.data.typecode})"
    if what == 7:
        msg.data = memoryview(data)[::2] if rng.random() < 0.5 else bytearray(data)
        return f"data {type(msg.data).__name__}"
    buf = bytearray(data)
    for _ in range(int(rng.integers(1, 20))):
        if buf:
            buf[int(rng.integers(len(buf)))] = int(rng.integers(256))
    msg.data = bytes(buf)
    return "random bytes flipped"


def _mut_endianness(rng, msg, rec):
    old = msg.is_bigendian
    msg.is_bigendian = _pick(rng, [not old, None, "yes", 2, np.bool_(not old)])
    return f"is_bigendian {old!r} -> {msg.is_bigendian!r}"


def _rewrite(msg, rec):
    """Re-encode ``rec`` into ``msg.data`` (after value mutations)."""
    height, width = msg.height, msg.width
    rows = np.zeros((height, msg.row_step), np.uint8)
    if rec.size:
        rows[:, : msg.point_step * width] = rec.view(np.uint8).reshape(height, -1)
    msg.data = rows.tobytes()


def _mut_values(rng, msg, rec):
    if rec.size == 0:
        return "values (empty cloud)"
    n = rec.size
    axis = _pick(rng, ["x", "y", "z"])
    kind = rec.dtype.fields[axis][0]
    huge = float(np.finfo(kind).max) if kind.kind == "f" else 1e30
    value = _pick(rng, [np.nan, np.inf, -np.inf, huge, -huge, 0.0, 1e-30, 1e19])
    idx = rng.random(n) < _pick(rng, [0.05, 0.5, 1.0])
    with np.errstate(over="ignore", invalid="ignore"):
        col = rec[axis].copy()
        col[idx] = value
        rec[axis] = col
        if rng.random() < 0.3:  # all three coordinates
            for a in "xyz":
                c = rec[a].copy()
                c[idx] = value
                rec[a] = c
    _rewrite(msg, rec)
    return f"{axis} = {value:g} on {int(idx.sum())}/{n} points"


def _mut_times(rng, msg, rec):
    names = [f for f in ("t", "time", "timestamp") if f in (rec.dtype.names or ())]
    if rec.size == 0 or not names:
        return "times (none)"
    f = names[0]
    kind = rec.dtype.fields[f][0]
    n = rec.size
    info = np.finfo(kind) if kind.kind == "f" else np.iinfo(kind)
    what = int(rng.integers(8))
    vals = rec[f].astype(np.float64)
    if what == 0:
        vals[:] = vals[0]
        text = "constant"
    elif what == 1:
        vals[0], vals[-1] = float(info.min), float(info.max)
        text = "first min, last max"
    elif what == 2:
        vals = np.where(np.arange(n) % 2 == 0, float(info.max), float(info.min))
        text = "alternating min/max"
    elif what == 3 and kind.kind == "f":
        vals[rng.random(n) < 0.3] = _pick(rng, [np.nan, np.inf, -np.inf])
        text = "non-finite times"
    elif what == 4:
        vals = vals[::-1].copy()
        text = "reversed"
    elif what == 5:
        vals = vals + (1.7e18 if kind.kind == "f" or info.max > 1e18 else float(info.max) / 2)
        text = "absolute times"
    elif what == 6:
        vals = rng.uniform(float(info.min) / 2, float(info.max) / 2, n)
        text = "random over the whole range"
    else:
        vals[int(rng.integers(n))] = float(info.max)
        text = "one time at max"
    with np.errstate(over="ignore", invalid="ignore"):
        rec[f] = vals.astype(kind) if kind.kind == "f" else np.clip(
            np.nan_to_num(vals), info.min, info.max).astype(kind)
    _rewrite(msg, rec)
    return f"{f} {text}"


MUTATIONS: list[Callable] = [_mut_field, _mut_sizes, _mut_data, _mut_endianness, _mut_values,
                             _mut_values, _mut_times, _mut_times]


def make_case(rng: np.random.Generator) -> tuple[SimpleNamespace, dict, str]:
    """(cloud message, parse keyword arguments, description)."""
    msg, rec, text = valid_cloud(rng)
    parts = [text]
    # value mutations first: they rewrite the payload from the records
    k = int(rng.integers(0, 4))
    muts = sorted((int(rng.integers(len(MUTATIONS))) for _ in range(k)),
                  key=lambda i: MUTATIONS[i] not in (_mut_values, _mut_times))
    for i in muts:
        try:
            parts.append(MUTATIONS[i](rng, msg, rec))
        except Exception:  # noqa: BLE001 - an earlier mutation left nothing to mutate
            parts.append(f"{MUTATIONS[i].__name__} not applicable")
    stamp = _pick(rng, [1.7e9, 1.7e9, 0.0, None, float("nan"), float("inf"), 1e308, -1e308])
    kwargs = {"stamp": stamp}
    if rng.random() < 0.3:
        kwargs["min_range"] = float(rng.uniform(0, 5))
        kwargs["max_range"] = float(rng.uniform(5, 100))
    parts.append(f"stamp {stamp!r}")
    return msg, kwargs, "; ".join(parts)


def check(parsed) -> str:
    """"" when ``parsed`` keeps its contract, else what is wrong."""
    n = len(parsed.xyz)
    if parsed.xyz.shape != (n, 3) or parsed.xyz.dtype != np.float64:
        return f"xyz shape {parsed.xyz.shape} dtype {parsed.xyz.dtype}"
    if parsed.times is not None and parsed.times.shape != (n,):
        return f"times shape {parsed.times.shape} for {n} points"
    s = parsed.stats
    total = (s.n_skipped + s.n_kept + s.n_nonfinite + s.n_zero_range + s.n_too_close
             + s.n_too_far + s.n_bad_time)
    if total != s.n_total or s.n_kept != n:
        return f"counters do not add up: {s}"
    return ""


def run_case(rng: np.random.Generator) -> Outcome:
    from lili_odom.pointcloud2 import CloudFormatError, parse_cloud

    msg, kwargs, case = make_case(rng)
    try:
        parsed = parse_cloud(msg, **kwargs)
    except Exception as exc:  # noqa: BLE001 - classified
        return from_exception(exc, (CloudFormatError,), case)
    if not (np.all(np.isfinite(parsed.xyz))
            and (parsed.times is None or np.all(np.isfinite(parsed.times)))):
        return Outcome(NONFINITE, "non-finite point or time kept", case)
    problem = check(parsed)
    if problem:
        return Outcome(INVALID, problem, case)
    return Outcome(CLEAN, f"{len(parsed)} points", case)
