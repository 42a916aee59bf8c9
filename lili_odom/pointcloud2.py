"""``sensor_msgs/PointCloud2`` content <-> numpy, without ROS.

The parser reads a cloud by its ``PointField`` list, so any layout works: the ouster-ros
"original" layout (x, y, z float32 @ 0/4/8, intensity float32 @ 16, ``t`` uint32 ns @ 20,
reflectivity/ring/ambient uint16 @ 24/26/28, ``range`` uint32 mm @ 32, point_step 48,
organized 128 x 1024) as well as plain x, y, z[, intensity][, t/time/timestamp] clouds, any
field datatype, either byte order, padded rows.

The input is *duck-typed*: any object with the attributes ``fields`` (items with ``name``,
``offset``, ``datatype``, ``count`` attributes, or ``(name, offset, datatype, count)`` tuples),
``is_bigendian``, ``point_step``, ``row_step``, ``height``, ``width`` and ``data`` (bytes,
bytearray, ``array.array`` as rclpy gives it, or a numpy uint8 array as rosbags gives it). A
real message of either library therefore works directly; :class:`CloudContent` is the plain
dataclass form used by tests and by :func:`encode_xyz_cloud`.

Frames and units: points stay in the message's frame (``os_lidar`` for the Ouster) in metres.
Per-point times are seconds relative to the message's ``header.stamp``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Sequence

import numpy as np

__all__ = [
    "CloudFormatError",
    "PointFieldSpec",
    "CloudContent",
    "ParseStats",
    "ParsedCloud",
    "DATATYPES",
    "parse_cloud",
    "encode_xyz_cloud",
]

# sensor_msgs/PointField datatype constants -> numpy base type (byte order applied later).
DATATYPES: dict[int, np.dtype] = {
    1: np.dtype(np.int8),  # INT8
    2: np.dtype(np.uint8),  # UINT8
    3: np.dtype(np.int16),  # INT16
    4: np.dtype(np.uint16),  # UINT16
    5: np.dtype(np.int32),  # INT32
    6: np.dtype(np.uint32),  # UINT32
    7: np.dtype(np.float32),  # FLOAT32
    8: np.dtype(np.float64),  # FLOAT64
}
FLOAT32 = 7
UINT32 = 6

# Field names holding a per-point time, in order of preference.
_TIME_FIELDS = ("t", "time", "timestamp")

# Sanity limits that keep garbage headers from allocating absurd amounts of memory.
_MAX_POINT_STEP = 1 << 16
_MAX_POINTS = 1 << 26

# Per-point time sanity. A sweep's times fill one contiguous span (0.1 s for a 10 Hz Ouster);
# a time farther than this fraction of the central span (1st..99th percentile) beyond it, plus
# _TIME_OUTLIER_FLOOR_S, is a corrupt value and its point is dropped. A central span longer
# than MAX_SWEEP_S means the whole time field is garbage: it is then ignored.
_TIME_OUTLIER_MARGIN = 0.1
_TIME_OUTLIER_FLOOR_S = 1e-3
_TIME_OUTLIER_MIN_POINTS = 20
MAX_SWEEP_S = 1.0


class CloudFormatError(ValueError):
    """The PointCloud2 content is malformed or lacks what the parser needs."""


class PointFieldSpec(NamedTuple):
    """One ``sensor_msgs/PointField``: ``offset`` in bytes inside a point, ``count`` elements."""

    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass
class CloudContent:
    """The parts of a ``sensor_msgs/PointCloud2`` the parser and encoder use (no header)."""

    fields: list[PointFieldSpec]
    is_bigendian: bool
    point_step: int
    row_step: int
    height: int
    width: int
    data: bytes
    is_dense: bool = False


@dataclass
class ParseStats:
    """Point counts of one parse.

    ``n_total`` = height * width; ``n_skipped`` + ``n_kept`` + every drop counter =
    ``n_total`` (each point is counted once, under the first reason that applies, in the order
    listed here).
    """

    n_total: int = 0
    n_skipped: int = 0  # left out by the point stride (not read, valid or not)
    n_nonfinite: int = 0  # NaN/Inf coordinates (ouster no-return pixels) or NaN time
    n_zero_range: int = 0  # xyz == 0 or a range field == 0 (older ouster drivers)
    n_too_close: int = 0  # norm(xyz) < min_range
    n_too_far: int = 0  # norm(xyz) > max_range
    n_bad_time: int = 0  # per-point time far outside the sweep's own time span (corrupt)
    n_kept: int = 0
    #: why the cloud's time field was not used ("" when it was, or when there is none): the
    #: points are then kept without per-point times (no deskewing).
    times_ignored: str = ""


@dataclass
class ParsedCloud:
    """Valid points of one cloud.

    Attributes:
        xyz: (N, 3) float64 points [m] in the message frame.
        times: (N,) float64 seconds relative to ``header.stamp``, or None when the cloud has no
            time field.
        intensity: (N,) float64 or None.
        range: (N,) float64 raw ``range`` field (ouster: millimetres) or None.
        ring: (N,) int64 ``ring`` field or None.
        index: (N,) int64 flat index (row * width + column) of each kept point in the message.
        time_field: name of the field the times came from ("" if none).
        time_scale: factor applied to the raw time values (1e-9 for nanoseconds, 1 for seconds).
        time_offset: seconds subtracted after scaling (non-zero only for absolute time stamps).
        stats: drop counters.
    """

    xyz: np.ndarray
    times: np.ndarray | None
    intensity: np.ndarray | None
    range: np.ndarray | None
    ring: np.ndarray | None
    index: np.ndarray
    time_field: str = ""
    time_scale: float = 1.0
    time_offset: float = 0.0
    stats: ParseStats = field(default_factory=ParseStats)

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


# --------------------------------------------------------------------------------------------
# input normalisation


def _as_int(value: Any, what: str) -> int:
    try:
        out = int(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise CloudFormatError(f"{what} is not an integer: {value!r}") from exc
    if isinstance(value, float) and value != out:
        raise CloudFormatError(f"{what} is not an integer: {value!r}")
    return out


def _field_specs(fields: Any) -> list[PointFieldSpec]:
    if fields is None:
        raise CloudFormatError("cloud has no fields")
    out: list[PointFieldSpec] = []
    try:
        items = list(fields)
    except TypeError as exc:
        raise CloudFormatError("fields is not a sequence") from exc
    for item in items:
        if hasattr(item, "name"):
            missing = [a for a in ("offset", "datatype") if not hasattr(item, a)]
            if missing:
                raise CloudFormatError(f"field {item.name!r} has no {missing[0]!r}")
            name, offset = item.name, item.offset
            datatype, count = item.datatype, getattr(item, "count", 1)
        else:
            try:
                parts = tuple(item)
            except TypeError as exc:
                raise CloudFormatError(f"bad field entry {item!r}") from exc
            if len(parts) not in (3, 4):
                raise CloudFormatError(f"bad field entry {item!r}")
            name, offset, datatype = parts[:3]
            count = parts[3] if len(parts) == 4 else 1
        if not isinstance(name, str):
            raise CloudFormatError(f"field name is not a string: {name!r}")
        out.append(
            PointFieldSpec(
                name,
                _as_int(offset, f"offset of field {name!r}"),
                _as_int(datatype, f"datatype of field {name!r}"),
                _as_int(count, f"count of field {name!r}"),
            )
        )
    return out


def _data_bytes(data: Any) -> np.ndarray:
    """Any buffer-like payload -> 1-D uint8 view (no copy when possible)."""
    if data is None:
        raise CloudFormatError("cloud has no data")
    if isinstance(data, np.ndarray):
        arr = data
        if arr.dtype != np.uint8:
            if arr.dtype.kind in "iu" and arr.dtype.itemsize == 1:
                arr = arr.view(np.uint8)
            else:
                raise CloudFormatError(f"data array has dtype {arr.dtype}, expected uint8")
        return np.ascontiguousarray(arr.reshape(-1))
    if isinstance(data, (list, tuple)):
        try:
            return np.asarray(data, dtype=np.uint8).reshape(-1)
        except (ValueError, OverflowError, TypeError) as exc:
            raise CloudFormatError("data list is not bytes") from exc
    try:
        view = memoryview(data)
    except TypeError as exc:
        raise CloudFormatError(f"data of type {type(data).__name__} is not a byte buffer") from exc
    if view.itemsize != 1:
        # array.array('B') has itemsize 1; anything wider is not a byte payload.
        raise CloudFormatError("data buffer items are not bytes")
    if not view.c_contiguous:
        return np.frombuffer(view.tobytes(), dtype=np.uint8)
    return np.frombuffer(view.cast("B"), dtype=np.uint8)


def _validate(msg: Any) -> tuple[list[PointFieldSpec], bool, int, int, int, int, np.ndarray]:
    """Check the layout; return (fields, big_endian, point_step, row_step, height, width, raw)."""
    for attr in ("fields", "is_bigendian", "point_step", "row_step", "height", "width", "data"):
        if not hasattr(msg, attr):
            raise CloudFormatError(f"cloud lacks attribute {attr!r}")
    fields = _field_specs(msg.fields)
    big = bool(msg.is_bigendian)
    point_step = _as_int(msg.point_step, "point_step")
    row_step = _as_int(msg.row_step, "row_step")
    height = _as_int(msg.height, "height")
    width = _as_int(msg.width, "width")
    raw = _data_bytes(msg.data)

    if min(point_step, row_step, height, width) < 0:
        raise CloudFormatError("negative point_step/row_step/height/width")
    if point_step > _MAX_POINT_STEP:
        raise CloudFormatError(f"point_step {point_step} is implausibly large")
    if height * width > _MAX_POINTS:
        raise CloudFormatError(f"{height} x {width} points is implausibly many")
    n_points = height * width
    if n_points > 0:
        if point_step == 0:
            raise CloudFormatError("point_step is 0 for a non-empty cloud")
        if row_step < point_step * width:
            raise CloudFormatError(
                f"row_step {row_step} < point_step {point_step} * width {width}"
            )
    if raw.size != row_step * height:
        raise CloudFormatError(
            f"data length {raw.size} != row_step {row_step} * height {height}"
        )
    names = set()
    for f in fields:
        if f.datatype not in DATATYPES:
            raise CloudFormatError(f"field {f.name!r} has unknown datatype {f.datatype}")
        if f.offset < 0 or f.count < 0:
            raise CloudFormatError(f"field {f.name!r} has a negative offset or count")
        end = f.offset + DATATYPES[f.datatype].itemsize * f.count
        if end > point_step:
            raise CloudFormatError(
                f"field {f.name!r} (offset {f.offset}, {f.count} x "
                f"{DATATYPES[f.datatype].itemsize} B) overruns point_step {point_step}"
            )
        names.add(f.name)
    for axis in ("x", "y", "z"):
        if axis not in names:
            raise CloudFormatError(f"cloud has no {axis!r} field")
        spec = next(f for f in fields if f.name == axis)
        if spec.count < 1:
            raise CloudFormatError(f"field {axis!r} has count 0")
    return fields, big, point_step, row_step, height, width, raw


# --------------------------------------------------------------------------------------------
# parsing


def _field_view(records: np.ndarray, spec: PointFieldSpec, big: bool, point_step: int
                ) -> np.ndarray:
    """First element of one field of every point: a strided view in the field's own type."""
    base = DATATYPES[spec.datatype].newbyteorder(">" if big else "<")
    dt = np.dtype({"names": ["v"], "formats": [base], "offsets": [spec.offset],
                   "itemsize": point_step})
    return records.view(dt)["v"]


def _read_float(records: np.ndarray, spec: PointFieldSpec, big: bool, point_step: int
                ) -> np.ndarray:
    """First element of one field of every point as contiguous float64 (integers of up to 32
    bits convert exactly, so this equals reading them as int64 first)."""
    return _field_view(records, spec, big, point_step).astype(np.float64)


def _read_xyz(records: np.ndarray, specs: Sequence[PointFieldSpec], big: bool,
              point_step: int) -> np.ndarray:
    """x, y, z of every point as an (N, 3) float64 array in column-major order (each column
    contiguous). Adjacent fields of one datatype (the usual layout) are read in one pass over
    the records as a 3-element subarray."""
    x, y, z = specs
    size = DATATYPES[x.datatype].itemsize
    if (x.datatype == y.datatype == z.datatype and y.offset == x.offset + size
            and z.offset == x.offset + 2 * size):
        base = DATATYPES[x.datatype].newbyteorder(">" if big else "<")
        dt = np.dtype({"names": ["v"], "formats": [(base, (3,))], "offsets": [x.offset],
                       "itemsize": point_step})
        return records.view(dt)["v"].astype(np.float64, order="F")
    out = np.empty((records.shape[0], 3), order="F")
    for column, spec in enumerate(specs):
        out[:, column] = _field_view(records, spec, big, point_step)
    return out


def _find(fields: Sequence[PointFieldSpec], name: str) -> PointFieldSpec | None:
    for f in fields:
        if f.name == name and f.count >= 1:
            return f
    return None


def _median_exceeds(values: np.ndarray, threshold: float) -> bool:
    """``np.median(values) > threshold`` for a non-empty array without NaN, in one pass.

    With more than half of the values above (at or below) the threshold, both middle values
    are, and so is their mean; only a tie at exactly half needs the median itself.
    """
    n = values.size
    above = int(np.count_nonzero(values > threshold))
    if 2 * above > n:
        return True
    if 2 * above < n:
        return False
    return bool(float(np.median(values)) > threshold)


def _time_conversion(raw_t: np.ndarray, spec: PointFieldSpec, stamp: float | None
                     ) -> tuple[float, float]:
    """Decide (scale, offset) so that ``raw * scale - offset`` is seconds since the stamp.

    Rules: integer fields are nanoseconds (ouster-ros ``t``). Floating fields are seconds
    unless the values span more than 10 units or exceed 1e12 in magnitude (a scan never lasts
    10 s, and no relative or absolute time in seconds reaches 1e12), in which case they are
    nanoseconds. After scaling, values above 1e5 s are absolute times: the header stamp is
    subtracted when given, otherwise the earliest point time (so times stay small and
    monotonic, relative to the first point instead of the stamp).
    """
    integer = DATATYPES[spec.datatype].kind in "iu"
    finite = raw_t if integer else raw_t[np.isfinite(raw_t)]
    if finite.size == 0:
        return 1.0, 0.0
    if integer:
        scale = 1e-9
    else:
        span = float(finite.max() - finite.min())
        scale = 1e-9 if (span > 10.0 or float(np.abs(finite).max()) > 1e12) else 1.0
    scaled = finite * scale
    if _median_exceeds(np.abs(scaled), 1e5):
        offset = float(stamp) if stamp is not None and math.isfinite(stamp) else float(
            scaled.min())
        return scale, offset
    return scale, 0.0


def parse_cloud(
    msg: Any,
    *,
    min_range: float = 0.0,
    max_range: float = math.inf,
    stamp: float | None = None,
    max_sweep_s: float = MAX_SWEEP_S,
    extra_fields: bool = True,
    stride: int = 1,
) -> ParsedCloud:
    """Parse PointCloud2 content into valid points and per-point times.

    Args:
        msg: duck-typed cloud (see module docstring).
        min_range: drop points closer than this to the sensor origin [m].
        max_range: drop points farther than this [m].
        stamp: the message's ``header.stamp`` in seconds; only needed for clouds whose time
            field holds absolute times (otherwise times are already relative to the stamp).
        max_sweep_s: longest plausible sweep [s]. Per-point times are checked against the
            sweep's own span: isolated values far outside it are corrupt (their points are
            dropped, ``stats.n_bad_time``); a time field with no finite value or a span
            longer than this is ignored (``times`` None, ``stats.times_ignored`` says why)
            and the points are kept.
        extra_fields: also return the ``intensity``, ``range`` and ``ring`` of the kept points;
            False leaves them None (the odometry uses points and times only). A ``range``
            field still marks zero-range points either way.
        stride: read only every ``stride``-th point of the cloud in its own order (row-major:
            in an organised Ouster cloud whose width is a multiple of ``stride``, every
            ``stride``-th column of each ring); the others are counted as
            ``stats.n_skipped``. 1 (default) reads every point.

    Returns:
        The kept points (NaN/Inf, zero-range, out-of-range and corrupt-time points removed)
        with counters.

    Raises:
        CloudFormatError: missing x/y/z, inconsistent point_step/row_step/data length, a field
            overrunning point_step, an unknown datatype, or a non-buffer payload.
        ValueError: a stride that is not a positive integer.
    """
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride must be a positive integer, got {stride!r}")
    stride = int(stride)
    fields, big, point_step, row_step, height, width, raw = _validate(msg)
    n_total = height * width
    stats = ParseStats(n_total=n_total)
    t_spec = next((s for s in (_find(fields, n) for n in _TIME_FIELDS) if s is not None), None)
    if n_total == 0:
        def empty(name: str, dtype: Any) -> np.ndarray | None:
            return None if _find(fields, name) is None else np.zeros(0, dtype)

        return ParsedCloud(
            np.zeros((0, 3)), None if t_spec is None else np.zeros(0), empty("intensity", float),
            empty("range", float), empty("ring", np.int64), np.zeros(0, np.int64),
            time_field=t_spec.name if t_spec is not None else "", stats=stats)

    rows = raw.reshape(height, row_step)[:, : point_step * width]
    records = np.ascontiguousarray(rows).reshape(n_total, point_step)
    records = records.view(np.dtype((np.void, point_step))).reshape(n_total)
    if stride > 1:
        records = records[::stride]  # a strided view: the skipped points are never read
        stats.n_skipped = n_total - records.shape[0]
    n_read = records.shape[0]

    # One contiguous float64 column per coordinate, read in one pass over the records:
    # every test below is element-wise on these columns (no (N, 3) reductions, no per-point
    # Python), and only the kept points are gathered into the (N, 3) output.
    xyz_all = _read_xyz(records, [_find(fields, a) for a in "xyz"], big, point_step)
    x, y, z = xyz_all[:, 0], xyz_all[:, 1], xyz_all[:, 2]

    times = None
    scale, offset = 1.0, 0.0
    if t_spec is not None:
        raw_t = _read_float(records, t_spec, big, point_step)
        scale, offset = _time_conversion(raw_t, t_spec, stamp)
        times = raw_t * scale - offset

    def optional(name: str) -> np.ndarray | None:
        spec = _find(fields, name)
        return None if spec is None else _field_view(records, spec, big, point_step)

    intensity = optional("intensity") if extra_fields else None
    rng = optional("range")
    ring = optional("ring") if extra_fields else None

    xyz_finite = np.isfinite(x)
    xyz_finite &= np.isfinite(y)
    xyz_finite &= np.isfinite(z)
    bad_time = np.zeros(n_read, dtype=bool)
    times_ignored = ""
    if times is not None:
        times, bad_time, times_ignored = _check_times(times, xyz_finite, max_sweep_s)
        if times is None:
            scale, offset = 1.0, 0.0

    with np.errstate(invalid="ignore", over="ignore"):
        finite = xyz_finite.copy()
        if times is not None:
            finite &= np.isfinite(times)
        # the Euclidean norm as np.linalg.norm computes it (sqrt of x^2 + y^2 + z^2 summed in
        # that order); only read where ``finite`` holds
        norm = x * x
        norm += y * y
        norm += z * z
        np.sqrt(norm, out=norm)
        zero = finite & (norm == 0.0)
        if rng is not None:
            zero |= finite & (rng == 0)
        rest = finite & ~zero
        too_close = rest & (norm < min_range)
        too_far = rest & (norm > max_range)
        # a norm that overflowed to inf counts as too far
        too_far |= rest & ~np.isfinite(norm)
    keep = rest & ~too_close & ~too_far
    bad_time &= keep  # counted once, under the first reason that applies
    keep &= ~bad_time

    stats.n_nonfinite = int(np.count_nonzero(~finite))
    stats.n_zero_range = int(np.count_nonzero(zero))
    stats.n_too_close = int(np.count_nonzero(too_close))
    stats.n_too_far = int(np.count_nonzero(too_far & ~too_close))
    stats.n_bad_time = int(np.count_nonzero(bad_time))
    stats.n_kept = int(np.count_nonzero(keep))
    stats.times_ignored = times_ignored

    index = np.flatnonzero(keep)

    def sel(a: np.ndarray | None, dtype: Any) -> np.ndarray | None:
        return None if a is None else a[index].astype(dtype)

    xyz = np.empty((len(index), 3))
    for column, values in enumerate((x, y, z)):
        np.take(values, index, out=xyz[:, column])
    return ParsedCloud(
        xyz=xyz,
        times=sel(times, np.float64),
        intensity=sel(intensity, np.float64),
        range=sel(rng, np.float64) if extra_fields else None,
        ring=sel(ring, np.int64),
        index=index.astype(np.int64) * stride,
        time_field=t_spec.name if t_spec is not None and times is not None else "",
        time_scale=scale,
        time_offset=offset,
        stats=stats,
    )


def _check_times(times: np.ndarray, xyz_finite: np.ndarray, max_sweep_s: float
                 ) -> tuple[np.ndarray | None, np.ndarray, str]:
    """Sanity of per-point times (seconds from the stamp) of the points with finite xyz.

    Returns ``(times or None, bad_time mask, reason)``: None with a reason when the whole field
    is unusable (no finite value, or a central span longer than ``max_sweep_s``); otherwise
    the mask of isolated corrupt values far outside the sweep's span (those points are
    dropped). Points with finite xyz but a non-finite time are left to the caller (dropped as
    non-finite) unless no time at all is finite.
    """
    bad = np.zeros(times.shape[0], dtype=bool)
    valid = times[xyz_finite]
    finite_t = valid[np.isfinite(valid)]
    if valid.size == 0:
        return times, bad, ""
    if finite_t.size == 0:
        return None, bad, "no finite per-point time"
    if finite_t.size >= _TIME_OUTLIER_MIN_POINTS:
        lo, hi = np.quantile(finite_t, [0.01, 0.99])
    else:
        lo, hi = float(np.median(finite_t)), float(np.median(finite_t))
    if not hi - lo <= max_sweep_s:
        return None, bad, (f"per-point times span {hi - lo:.3g} s, more than a sweep "
                           f"({max_sweep_s:g} s)")
    margin = _TIME_OUTLIER_MARGIN * (hi - lo) + _TIME_OUTLIER_FLOOR_S
    if finite_t.size < _TIME_OUTLIER_MIN_POINTS:
        margin = max(margin, max_sweep_s)  # too few points for statistics: only the hard limit
    with np.errstate(invalid="ignore"):
        bad = np.isfinite(times) & ((times < lo - margin) | (times > hi + margin))
    return times, bad, ""


# --------------------------------------------------------------------------------------------
# encoding


def encode_xyz_cloud(
    xyz: np.ndarray,
    times: np.ndarray | None = None,
    intensity: np.ndarray | None = None,
    *,
    big_endian: bool = False,
) -> CloudContent:
    """Pack points into a plain unorganized cloud (height 1).

    Layout: x, y, z float32 @ 0/4/8, then optional ``intensity`` float32, then optional
    ``time`` float32 [s relative to the header stamp] — readable by rviz, PCL and
    :func:`parse_cloud`. Copy the result's attributes into a ``sensor_msgs/PointCloud2``.

    Args:
        xyz: (N, 3) points [m].
        times: optional (N,) per-point times [s].
        intensity: optional (N,) intensities.
        big_endian: byte order of the payload.
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    names = ["x", "y", "z"]
    columns = [xyz[:, 0], xyz[:, 1], xyz[:, 2]]
    if intensity is not None:
        names.append("intensity")
        columns.append(np.asarray(intensity, dtype=np.float64).reshape(n))
    if times is not None:
        names.append("time")
        columns.append(np.asarray(times, dtype=np.float64).reshape(n))
    order = ">" if big_endian else "<"
    dtype = np.dtype([(name, order + "f4") for name in names])
    rec = np.empty(n, dtype=dtype)
    for name, col in zip(names, columns):
        rec[name] = col
    fields = [PointFieldSpec(name, 4 * i, FLOAT32, 1) for i, name in enumerate(names)]
    step = dtype.itemsize
    return CloudContent(
        fields=fields,
        is_bigendian=big_endian,
        point_step=step,
        row_step=step * n,
        height=1,
        width=n,
        data=rec.tobytes(),
        is_dense=bool(np.all(np.isfinite(xyz))),
    )
