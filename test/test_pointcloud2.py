"""PointCloud2 content parsing: ouster layout, plain layouts, random layouts, garbage."""
from __future__ import annotations

import array
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lili_odom.pointcloud2 import (
    DATATYPES,
    CloudContent,
    CloudFormatError,
    PointFieldSpec,
    encode_xyz_cloud,
    parse_cloud,
)


def ouster_cloud(height: int = 4, width: int = 8, zeros_for_missing: bool = False,
                 big: bool = False) -> tuple[CloudContent, np.ndarray, np.ndarray]:
    """An ouster-ros 'original' layout cloud; every third pixel has no return."""
    o = ">" if big else "<"
    dtype = np.dtype({
        "names": ["x", "y", "z", "intensity", "t", "reflectivity", "ring", "ambient", "range"],
        "formats": [o + "f4", o + "f4", o + "f4", o + "f4", o + "u4", o + "u2", o + "u2",
                    o + "u2", o + "u4"],
        "offsets": [0, 4, 8, 16, 20, 24, 26, 28, 32],
        "itemsize": 48,
    })
    rng = np.random.default_rng(0)
    n = height * width
    xyz = rng.uniform(-20, 20, (n, 3)).astype(np.float32)
    t_ns = (np.tile(np.arange(width), height) * (100_000_000 // width)).astype(np.uint32)
    rec = np.zeros(n, dtype=dtype)
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["intensity"] = np.arange(n)
    rec["t"] = t_ns
    rec["ring"] = np.repeat(np.arange(height), width)
    rec["range"] = (np.linalg.norm(xyz.astype(np.float64), axis=1) * 1000).astype(np.uint32)
    missing = np.arange(n) % 3 == 0
    if zeros_for_missing:
        for a in "xyz":
            rec[a][missing] = 0.0
        rec["range"][missing] = 0
    else:
        for a in "xyz":
            rec[a][missing] = np.nan
    fields = [PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7), PointFieldSpec("z", 8, 7),
              PointFieldSpec("intensity", 16, 7), PointFieldSpec("t", 20, 6),
              PointFieldSpec("reflectivity", 24, 4), PointFieldSpec("ring", 26, 4),
              PointFieldSpec("ambient", 28, 4), PointFieldSpec("range", 32, 6)]
    msg = CloudContent(fields, big, 48, 48 * width, height, width, rec.tobytes())
    return msg, xyz[~missing].astype(np.float64), t_ns[~missing] * 1e-9


@pytest.mark.parametrize("zeros", [False, True])
@pytest.mark.parametrize("big", [False, True])
def test_ouster_original_layout(zeros: bool, big: bool) -> None:
    msg, xyz, t = ouster_cloud(zeros_for_missing=zeros, big=big)
    out = parse_cloud(msg)
    np.testing.assert_array_equal(out.xyz, xyz)
    np.testing.assert_allclose(out.times, t, atol=1e-12)
    assert out.time_field == "t" and out.time_scale == 1e-9
    assert out.ring is not None and out.range is not None and out.intensity is not None
    s = out.stats
    assert s.n_total == 32 and s.n_kept == len(xyz)
    assert (s.n_zero_range if zeros else s.n_nonfinite) == 32 - len(xyz)
    assert s.n_kept + s.n_nonfinite + s.n_zero_range + s.n_too_close + s.n_too_far == s.n_total



@pytest.mark.parametrize("big", [False, True])
def test_without_extra_fields_same_points(big: bool) -> None:
    """extra_fields=False: same points, times and counts; intensity/range/ring left out, and
    the range field still marks zero-range points."""
    msg, xyz, t = ouster_cloud(zeros_for_missing=True, big=big)
    full, lean = parse_cloud(msg), parse_cloud(msg, extra_fields=False)
    np.testing.assert_array_equal(lean.xyz, full.xyz)
    np.testing.assert_array_equal(lean.times, full.times)
    np.testing.assert_array_equal(lean.index, full.index)
    assert lean.intensity is None and lean.range is None and lean.ring is None
    assert vars(lean.stats) == vars(full.stats) and lean.stats.n_zero_range > 0


@pytest.mark.parametrize("stride", [1, 2, 3, 8, 40])
@pytest.mark.parametrize("big", [False, True])
def test_stride_reads_every_nth_point(stride: int, big: bool) -> None:
    """stride n: exactly the points of the whole cloud's parse at flat indices that are
    multiples of n, with their times and indices; the others counted as skipped."""
    msg, _, _ = ouster_cloud(height=4, width=10, zeros_for_missing=True, big=big)
    full, strided = parse_cloud(msg), parse_cloud(msg, stride=stride)
    read = full.index % stride == 0
    np.testing.assert_array_equal(strided.xyz, full.xyz[read])
    np.testing.assert_array_equal(strided.times, full.times[read])
    np.testing.assert_array_equal(strided.index, full.index[read])
    np.testing.assert_array_equal(strided.ring, full.ring[read])
    s = strided.stats
    assert s.n_total == 40 and s.n_skipped == 40 - len(range(0, 40, stride))
    assert (s.n_skipped + s.n_kept + s.n_nonfinite + s.n_zero_range + s.n_too_close
            + s.n_too_far + s.n_bad_time) == s.n_total


@pytest.mark.parametrize("stride", [0, -1, 1.5, True, "2"])
def test_stride_must_be_a_positive_integer(stride) -> None:
    msg, _, _ = ouster_cloud()
    with pytest.raises(ValueError, match="stride"):
        parse_cloud(msg, stride=stride)


def test_xyz_in_any_field_order() -> None:
    """x, y, z not adjacent or of mixed types read the same as the packed layout."""
    rng = np.random.default_rng(3)
    xyz = rng.uniform(-20, 20, (50, 3)).astype(np.float32)
    rec = np.zeros(50, dtype={"names": ["z", "pad", "x", "y"],
                              "formats": ["<f8", "<u2", "<f4", "<f4"],
                              "offsets": [0, 8, 12, 20], "itemsize": 28})
    rec["x"], rec["y"], rec["z"] = xyz.T
    fields = [PointFieldSpec("z", 0, 8), PointFieldSpec("x", 12, 7), PointFieldSpec("y", 20, 7)]
    out = parse_cloud(CloudContent(fields, False, 28, 28 * 50, 1, 50, rec.tobytes()))
    np.testing.assert_array_equal(out.xyz, xyz.astype(np.float64))
    assert out.xyz.flags.c_contiguous


@pytest.mark.parametrize("values", [[1.0, 2e5, 3e5, 4.0], [1.0, 1e5, 2e5, 3e5], [1.0, 2.0, 3e5],
                                    [2e5, 3e5, 1.0], [1e5 - 1, 1e5 + 3], [7.0]])
def test_median_threshold_matches_numpy(values: list) -> None:
    from lili_odom.pointcloud2 import _median_exceeds

    a = np.asarray(values)
    assert _median_exceeds(a, 1e5) == (np.median(a) > 1e5)

def test_message_like_objects_and_payload_types() -> None:
    msg, xyz, _ = ouster_cloud()
    fields = [SimpleNamespace(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
              for f in msg.fields]
    for data in (np.frombuffer(msg.data, np.uint8), array.array("B", msg.data),
                 bytearray(msg.data), memoryview(msg.data)):
        like = SimpleNamespace(fields=fields, is_bigendian=False, point_step=48,
                               row_step=msg.row_step, height=msg.height, width=msg.width,
                               data=data)
        np.testing.assert_array_equal(parse_cloud(like).xyz, xyz)


def test_range_filter_counts() -> None:
    pts = np.array([[0.5, 0, 0], [5, 0, 0], [50, 0, 0], [0, 0, 0], [np.inf, 0, 0]])
    out = parse_cloud(encode_xyz_cloud(pts), min_range=1.0, max_range=20.0)
    np.testing.assert_array_equal(out.xyz, [[5, 0, 0]])
    s = out.stats
    assert (s.n_too_close, s.n_too_far, s.n_zero_range, s.n_nonfinite, s.n_kept) == (1, 1, 1, 1, 1)
    np.testing.assert_array_equal(out.index, [1])


@pytest.mark.parametrize("big", [False, True])
def test_encode_round_trip(big: bool) -> None:
    rng = np.random.default_rng(1)
    xyz = rng.normal(size=(100, 3)) * 10
    t = np.linspace(-0.05, 0.05, 100)
    out = parse_cloud(encode_xyz_cloud(xyz, times=t, intensity=np.arange(100.0), big_endian=big))
    np.testing.assert_allclose(out.xyz, xyz.astype(np.float32), rtol=0, atol=0)
    np.testing.assert_allclose(out.times, t.astype(np.float32))
    np.testing.assert_array_equal(out.intensity, np.arange(100.0))


def test_time_units_by_magnitude() -> None:
    xyz = np.ones((5, 3))
    ns = np.linspace(0, 1e8, 5)  # 0..100 ms as float nanoseconds
    msg = encode_xyz_cloud(xyz, times=ns)
    np.testing.assert_allclose(parse_cloud(msg).times, ns * 1e-9, rtol=1e-6)
    # absolute float64 seconds (hesai/velodyne style 'timestamp')
    stamp = 1.7e9
    rec = np.zeros(5, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("timestamp", "<f8")])
    rec["x"] = 1.0
    rec["timestamp"] = stamp + np.linspace(0, 0.1, 5)
    fields = [PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7), PointFieldSpec("z", 8, 7),
              PointFieldSpec("timestamp", 12, 8)]
    msg = CloudContent(fields, False, 20, 100, 1, 5, rec.tobytes())
    np.testing.assert_allclose(parse_cloud(msg, stamp=stamp).times, np.linspace(0, 0.1, 5),
                               atol=1e-6)
    np.testing.assert_allclose(parse_cloud(msg).times, np.linspace(0, 0.1, 5), atol=1e-6)


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(fields=[PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7)]), "'z'"),
        (dict(point_step=8), "overruns"),
        (dict(row_step=10), "row_step"),
        (dict(data=b"\x00" * 7), "data length"),
        (dict(fields=[PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7),
                      PointFieldSpec("z", 8, 42)]), "datatype"),
        (dict(fields=[PointFieldSpec("x", 0, 7), PointFieldSpec("y", 4, 7),
                      PointFieldSpec("z", 10, 7)]), "overruns"),
        (dict(data="not bytes"), "byte buffer"),
    ],
)
def test_format_errors(change: dict, match: str) -> None:
    msg = encode_xyz_cloud(np.ones((3, 3)))
    with pytest.raises(CloudFormatError, match=match):
        parse_cloud(replace(msg, **change))


# --------------------------------------------------------------------------------------------
# property tests

_INT_RANGES = {1: (-128, 127), 2: (0, 255), 3: (-2000, 2000), 4: (0, 4000), 5: (-10**6, 10**6),
               6: (0, 10**6), 7: None, 8: None}


@st.composite
def random_layouts(draw):
    """A random cloud layout plus the values written into it."""
    names = ["x", "y", "z"] + draw(st.lists(st.sampled_from(["intensity", "ring", "pad", "t"]),
                                            unique=True, max_size=3))
    names = draw(st.permutations(names))
    types = {n: draw(st.sampled_from(sorted(DATATYPES))) for n in names}
    if "t" in types:
        types["t"] = 6  # ouster style uint32 nanoseconds
    offset = 0
    fields = []
    for n in names:
        size = DATATYPES[types[n]].itemsize
        offset += draw(st.integers(0, 3))
        count = draw(st.integers(1, 2))
        fields.append(PointFieldSpec(n, offset, types[n], count))
        offset += size * count
    point_step = offset + draw(st.integers(0, 5))
    height = draw(st.integers(0, 3))
    width = draw(st.integers(0, 6))
    row_pad = draw(st.integers(0, 7))
    big = draw(st.booleans())
    return fields, point_step, height, width, row_pad, big


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_layouts(), st.integers(0, 2**32 - 1))
def test_random_layout_round_trip(layout, seed) -> None:
    fields, point_step, height, width, row_pad, big = layout
    rng = np.random.default_rng(seed)
    n = height * width
    o = ">" if big else "<"
    values = {}
    row_step = point_step * width + row_pad
    buf = bytearray(row_step * height)
    for f in fields:
        base = DATATYPES[f.datatype]
        lim = _INT_RANGES[f.datatype]
        if f.name == "t":
            v = rng.integers(0, 100_000_000, n)
        elif lim is None:
            v = rng.uniform(1.0, 100.0, n) * rng.choice([-1, 1], n)
        else:
            lo, hi = lim
            lo = max(lo, 1) if f.name in "xyz" else lo  # keep points off the origin
            v = rng.integers(lo, hi + 1, n)
        v = v.astype(base)
        values[f.name] = v
        enc = v.astype(base.newbyteorder(o)).tobytes()
        s = base.itemsize
        for i in range(n):
            r, c = divmod(i, width)
            pos = r * row_step + c * point_step + f.offset
            buf[pos:pos + s] = enc[i * s:(i + 1) * s]
    msg = CloudContent(fields, big, point_step, row_step, height, width, bytes(buf))
    out = parse_cloud(msg)
    assert out.stats.n_total == n
    expect = np.stack([values[a].astype(np.float64) for a in "xyz"], axis=1).reshape(n, 3)
    np.testing.assert_array_equal(out.xyz, expect)
    if "t" in values:
        np.testing.assert_allclose(out.times, values["t"] * 1e-9)
    if "ring" in values:
        np.testing.assert_array_equal(out.ring, values["ring"].astype(np.int64))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from(["x", "y", "z", "t", "time", "range", "q"]),
                       st.integers(-4, 40), st.integers(-1, 12), st.integers(-1, 3)),
             max_size=6),
    st.integers(-2, 60), st.integers(-5, 400), st.integers(-1, 5), st.integers(-1, 5),
    st.binary(max_size=400), st.booleans(),
)
def test_garbage_only_raises_cloud_format_error(fields, point_step, row_step, height, width,
                                                data, big) -> None:
    msg = SimpleNamespace(fields=fields, is_bigendian=big, point_step=point_step,
                          row_step=row_step, height=height, width=width, data=data)
    try:
        out = parse_cloud(msg, min_range=0.1, max_range=100.0)
    except CloudFormatError:
        return
    assert out.xyz.shape[1] == 3 and np.all(np.isfinite(out.xyz))
    if out.times is not None:
        assert np.all(np.isfinite(out.times))


def test_garbage_without_attributes() -> None:
    with pytest.raises(CloudFormatError):
        parse_cloud(object())
    with pytest.raises(CloudFormatError):
        parse_cloud(SimpleNamespace(fields=[object()], is_bigendian=0, point_step=12,
                                    row_step=12, height=1, width=1, data=b"\0" * 12))
