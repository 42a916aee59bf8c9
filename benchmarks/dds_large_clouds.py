"""How many full-resolution Ouster clouds cross DDS between two processes, per DDS setup.

Each case runs ``python -m lili_odom.ros.cloud_check receive`` (the node's subscription QoS:
best effort, depth 10, unless the case says reliable) and ``... publish`` (128 x 1024 clouds
in the ouster-ros "original" layout, 6.3 MB, at 10 Hz) as two processes on this machine, each
with its own environment, in an isolated domain (localhost only), and counts the clouds that
arrive, and how long each takes from its publication (its stamp: the publisher's wall clock)
to the receiving callback with the decoded cloud. Cases:

* ``fastdds_default``: Fast DDS's own defaults on both sides (shared memory + UDP), best effort
* ``large_data``: ``FASTDDS_BUILTIN_TRANSPORTS=LARGE_DATA`` on both sides, best effort
* ``profile_subscriber_only``: the package profile in the receiving process only
* ``profile_publisher_only``: the package profile in the publishing process only
* ``profile_both``: the package's defaults (node and publisher load the profile), best effort
* ``reliable_fastdds_default``: Fast DDS defaults, reliable publisher and subscriber
* ``reliable_to_best_effort_*``: a reliable publisher (``lili-odom play``'s default) and the
  node's best-effort subscription, with Fast DDS's defaults and with the package profile
* ``*_raw``: as the case without the suffix, the clouds taken as serialised bytes and decoded
  by rosbags (as ``lili_odom_node`` does) instead of converted by rclpy

Cases named with ``--cases`` replace their rows in an existing result file.

Writes ``benchmarks/results/dds_large_clouds.json`` and ``.md``.

    python -m benchmarks.dds_large_clouds                 # all cases, 100 clouds each (~3 min)
    python -m benchmarks.dds_large_clouds --count 50 --cases fastdds_default profile_both
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import random
import subprocess
import sys
import time
from pathlib import Path

from benchmarks._common import RESULTS, ROOT
from lili_odom.ros.dds import profile_path

CASES = {
    # name: (publisher env, subscriber env, publisher qos, reliable subscription[, decode])
    "fastdds_default": ({}, {}, "sensor-data", False),
    "large_data": ({"FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA"},
                   {"FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA"}, "sensor-data", False),
    "profile_subscriber_only": ({}, {"profile": "1"}, "sensor-data", False),
    "profile_publisher_only": ({"profile": "1"}, {}, "sensor-data", False),
    "profile_both": ({"profile": "1"}, {"profile": "1"}, "sensor-data", False),
    "reliable_fastdds_default": ({}, {}, "reliable", True),
    # `lili-odom play` (reliable) into the node's default best-effort subscription
    "reliable_to_best_effort_fastdds_default": ({}, {}, "reliable", False),
    "reliable_to_best_effort_profile_both": ({"profile": "1"}, {"profile": "1"}, "reliable",
                                             False),
    "profile_both_raw": ({"profile": "1"}, {"profile": "1"}, "sensor-data", False, "raw"),
    # `lili-odom play` into the node with `reliable_inputs` (the node latency benchmark)
    "reliable_profile_both": ({"profile": "1"}, {"profile": "1"}, "reliable", True),
    "reliable_profile_both_raw": ({"profile": "1"}, {"profile": "1"}, "reliable", True, "raw"),
}
_DDS_VARS = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
             "FASTDDS_BUILTIN_TRANSPORTS", "LILI_ODOM_DDS_PROFILE")


def _env(base: dict[str, str], extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in base.items() if k not in _DDS_VARS}
    extra = dict(extra)
    if extra.pop("profile", None):
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile_path())
    else:
        env["LILI_ODOM_DDS_PROFILE"] = "0"  # the middleware's own defaults
    env.update(extra)
    return env


def run_case(name: str, count: int, rate: float, height: int, width: int) -> dict:
    pub_extra, sub_extra, qos, reliable_sub, *rest = CASES[name]
    decode = rest[0] if rest else "rclpy"
    base = dict(os.environ)
    base["ROS_DOMAIN_ID"] = str(random.randint(100, 200))
    base["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    base.pop("ROS_STATIC_PEERS", None)
    base["PYTHONPATH"] = str(ROOT) + os.pathsep + base.get("PYTHONPATH", "")
    cli = [sys.executable, "-m", "lili_odom.ros.cloud_check"]
    shape = ["--count", str(count), "--rate", str(rate), "--height", str(height),
             "--width", str(width)]
    recv = subprocess.Popen(cli + ["receive", *shape, "--timeout", str(count / rate + 40),
                                   "--decode", decode, "--stamp-now"]
                            + (["--reliable-sub"] if reliable_sub else []),
                            env=_env(base, sub_extra), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    pub = subprocess.run(cli + ["publish", *shape, "--qos", qos, "--stamp-now"],
                         env=_env(base, pub_extra),
                         capture_output=True, text=True, timeout=count / rate + 60)
    recv.wait(timeout=count / rate + 60) if pub.returncode == 0 else recv.kill()
    out, err = recv.communicate()
    if pub.returncode != 0 or recv.returncode != 0:
        return {"case": name, "error": (pub.stderr + err).strip()[-400:]}
    result = json.loads(out.strip().splitlines()[-1])
    result.update({"case": name, "publisher_qos": qos, "reliable_subscription": reliable_sub})
    for key in ("profile", "builtin_transports", "qos"):
        result.pop(key, None)
    return result


def render(doc: dict) -> str:
    lines = ["# Full-resolution clouds across processes (DDS)", "",
             f"`python -m benchmarks.dds_large_clouds` on {doc['machine']}; "
             f"{doc['height']} x {doc['width']} clouds ({doc['bytes_per_cloud'] / 1e6:.1f} MB) "
             f"at {doc['rate_hz']:g} Hz, {doc['count']} per case, Fast DDS {doc['fastdds']}.", "",
             "Latency: from publication (the stamp, the publisher's wall clock) to the receiving "
             "callback holding the decoded cloud, over the clouds received [ms]; decode: rclpy's "
             "message conversion, or the serialised bytes decoded by rosbags (`raw`, as "
             "`lili_odom_node` takes its clouds).", "",
             "| case | publisher QoS | subscription | decode | received | fraction | "
             "latency p50 / p99 / mean [ms] |",
             "|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        if "error" in r:
            lines.append(f"| {r['case']} | | | | error: {r['error'][:80]} | | |")
            continue
        lat = r.get("latency_ms")
        lat = f"{lat['p50']:.1f} / {lat['p99']:.1f} / {lat['mean']:.1f}" if lat else "–"
        lines.append(f"| {r['case']} | {r['publisher_qos']} | "
                     f"{'reliable' if r['reliable_subscription'] else 'best effort'} | "
                     f"{r.get('decode', 'rclpy')} | {r['received']} / {r['published']} | "
                     f"{r['fraction']:.2f} | {lat} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--out", type=Path, default=RESULTS / "dds_large_clouds.json")
    a = p.parse_args()
    rows = []
    if a.out.is_file() and set(a.cases) != set(CASES):
        old = json.loads(a.out.read_text())
        if (old["count"], old["rate_hz"], old["height"], old["width"]) == (
                a.count, a.rate, a.height, a.width):
            rows = [r for r in old["rows"] if r["case"] not in a.cases]
    for name in a.cases:
        row = run_case(name, a.count, a.rate, a.height, a.width)
        print(json.dumps(row), flush=True)
        rows.append(row)
    rows.sort(key=lambda r: list(CASES).index(r["case"]))
    try:
        from importlib.metadata import version

        fastdds = version("ros-fastrtps")
    except Exception:  # noqa: BLE001 - a colcon install has no pip metadata
        fastdds = "unknown"
    doc = {"count": a.count, "rate_hz": a.rate, "height": a.height, "width": a.width,
           "bytes_per_cloud": a.height * a.width * 48, "fastdds": fastdds,
           "machine": f"{platform.machine()}, {os.cpu_count()} cores", "rows": rows}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(doc, indent=1) + "\n")
    a.out.with_suffix(".md").write_text(render(doc))
    print(render(doc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
