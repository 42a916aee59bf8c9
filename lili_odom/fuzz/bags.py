"""Door ``bags``: truncated, corrupt and mistyped rosbag2 bags into ``lili-odom run``.

A case copies the committed CI bag (``bags/tunnel_entrance_32x256``, rosbag2 directory with one
MCAP file) into a temporary directory, breaks it (truncated file, flipped or zeroed bytes in the
first chunks or in the summary, a broken or mistyped ``metadata.yaml``, an empty or random
file, no metadata, a missing path, a parameter file that remaps the LiDAR topic to a topic of
another type) and runs ``lili-odom run BAG --method none --max-scans 6`` through
:func:`lili_odom.cli.main` in this process. Expected: exit code 0, or exit code 2 with one
line on stderr (a :class:`~lili_odom.errors.UserError`); no exception escapes.
"""
from __future__ import annotations

import contextlib
import io
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from lili_odom.fuzz.outcome import CLEAN, DOCUMENTED, OTHER, Outcome, from_exception, one_line

ROOT = Path(__file__).resolve().parents[2]
SOURCE_BAG = ROOT / "bags" / "tunnel_entrance_32x256"
MAX_SCANS = 6


def _pick(rng: np.random.Generator, options: list) -> Any:
    return options[int(rng.integers(len(options)))]


def _flip(path: Path, rng: np.random.Generator, lo: int, hi: int, count: int,
          zero: bool = False) -> None:
    size = path.stat().st_size
    lo, hi = max(0, min(lo, size)), max(0, min(hi, size))
    if hi <= lo:
        return
    with path.open("r+b") as f:
        if zero:
            start = int(rng.integers(lo, hi))
            length = int(rng.integers(1, 65536))
            f.seek(start)
            f.write(bytes(min(length, size - start)))
            return
        for pos in rng.integers(lo, hi, count):
            f.seek(int(pos))
            f.write(bytes([int(rng.integers(256))]))


def make_case(rng: np.random.Generator, work: Path) -> tuple[Path, list[str], str]:
    """Build a broken bag under ``work``: (bag path, extra CLI arguments, description)."""
    bag = work / "bag"
    mcap_name = f"{SOURCE_BAG.name}.mcap"
    src_mcap = SOURCE_BAG / mcap_name
    size = src_mcap.stat().st_size
    bag.mkdir()
    meta = (SOURCE_BAG / "metadata.yaml").read_text()
    what = int(rng.integers(12))
    mcap = bag / mcap_name
    if what == 0:
        k = int(rng.integers(0, size))
        with src_mcap.open("rb") as fi, mcap.open("wb") as fo:
            fo.write(fi.read(k))
        (bag / "metadata.yaml").write_text(meta)
        return bag, [], f"mcap truncated to {k} of {size} bytes"
    shutil.copyfile(src_mcap, mcap)
    if what in (1, 2, 3):
        region = _pick(rng, [(0, 3_000_000, "first chunks"), (size - 65536, size, "summary"),
                             (0, size, "anywhere")])
        count = int(rng.integers(1, 50))
        _flip(mcap, rng, region[0], region[1], count, zero=what == 3)
        (bag / "metadata.yaml").write_text(meta)
        return bag, [], f"{'zeroed block' if what == 3 else f'{count} bytes flipped'} in the " \
                        f"{region[2]}"
    if what == 4:
        k = int(rng.integers(0, len(meta)))
        (bag / "metadata.yaml").write_text(meta[:k])
        return bag, [], f"metadata.yaml truncated to {k} chars"
    if what == 5:
        (bag / "metadata.yaml").write_bytes(rng.integers(0, 256, int(rng.integers(0, 500)),
                                                         dtype=np.uint8).tobytes())
        return bag, [], "metadata.yaml random bytes"
    if what == 6:
        edit = _pick(rng, [("name: /ouster/points", "name: /ouster/pointz"),
                           ("type: sensor_msgs/msg/PointCloud2", "type: sensor_msgs/msg/Imu"),
                           (mcap_name, "missing.mcap"), ("storage_identifier: mcap",
                                                         "storage_identifier: sqlite3"),
                           ("version: ", "version: 99 #"), ("rosbag2_bagfile_information",
                                                            "something_else")])
        (bag / "metadata.yaml").write_text(meta.replace(*edit))
        return bag, [], f"metadata.yaml {edit[0]!r} -> {edit[1]!r}"
    if what == 7:
        (bag / "metadata.yaml").write_text(meta)
        mcap.write_bytes(b"" if rng.random() < 0.5 else rng.integers(
            0, 256, int(rng.integers(1, 100_000)), dtype=np.uint8).tobytes())
        return bag, [], "mcap empty or random bytes"
    if what == 8:
        return bag, [], "directory without metadata.yaml"
    if what == 9:
        single = _pick(rng, [work / "nope", work / "x.txt", work / "x.db3", mcap])
        if single.suffix in (".txt", ".db3"):
            single.write_bytes(rng.integers(0, 256, 1000, dtype=np.uint8).tobytes())
        elif single == mcap:
            _flip(mcap, rng, size - 65536, size, 20)
        return single, [], f"path {single.name}"
    if what == 10:
        (bag / "metadata.yaml").write_text(meta)
        topic = _pick(rng, ["/ouster/imu", "/platform/odom", "/tf_static", "/nothing"])
        params = work / "params.yaml"
        params.write_text(f"lili_odom:\n  ros__parameters:\n    lidar_topic: {topic}\n")
        return bag, ["--config", str(params)], f"lidar_topic remapped to {topic}"
    (bag / "metadata.yaml").write_text(meta)
    params = work / "params.yaml"
    params.write_text(_pick(rng, ["lili_odom: [1, 2\n", "lili_odom:\n  ros__parameters:\n"
                                  "    pipeline:\n      min_points: -5\n", "\x00\x01",
                                  "lili_odom:\n  ros__parameters:\n    nonsense_key: 1\n"]))
    return bag, ["--config", str(params)], "bad parameter file"


def run_case(rng: np.random.Generator) -> Outcome:
    from lili_odom.cli import main

    with tempfile.TemporaryDirectory(prefix="lili_fuzz_bag_") as tmp:
        work = Path(tmp)
        bag, extra, case = make_case(rng, work)
        argv = ["run", str(bag), "--method", "none", "--out", str(work / "out"),
                "--max-scans", str(MAX_SCANS), "--no-progress", *extra]
        err, out = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
                code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
        except Exception as exc:  # noqa: BLE001 - classified
            return from_exception(exc, (), case)
    err = io.StringIO(err.getvalue().replace(str(work), "<tmp>"))
    lines = [ln for ln in err.getvalue().splitlines() if ln.startswith("lili-odom run: error:")]
    if code == 0:
        return Outcome(CLEAN, one_line(out.getvalue().strip().splitlines()[-1:] or ""), case)
    if code == 2 and len(lines) == 1:
        return Outcome(DOCUMENTED, one_line(lines[0]), case, "UserError")
    return Outcome(OTHER, f"exit code {code}: {one_line(err.getvalue()[-300:])}", case)
