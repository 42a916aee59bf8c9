"""What one ``~/path`` publication costs the node's processing thread, by path length.

    python -m benchmarks.studies.path_publication
    python -m benchmarks.studies.path_publication --poses 1000 5000 20000 --repeats 5

The node keeps one ``geometry_msgs/PoseStamped`` per processed scan and publishes the path,
evenly thinned to ``path_max_poses`` poses, every ``path_period`` s from the thread that
processes the scans (:meth:`lili_odom.ros.node.LiliOdomNode._publish`). For each path length
``n`` this builds ``2 n`` pose messages with the rclpy message factory
(:class:`lili_odom.ros.factory.RclpyFactory`; the node keeps up to ``4 n`` before it thins
what it keeps), then times what a publication of ``n`` poses does in Python and rclpy:
thinning to ``n`` (:func:`lili_odom.bagio.writer.thin_poses`), the ``nav_msgs/Path``
(:func:`lili_odom.messages.path_of`) and its serialisation (``rclpy.serialization``, the
conversion to the C message every ``publish`` makes). Median of ``--repeats`` [ms]; the DDS
write itself is not included. Needs the ROS 2 Python packages (``make install-ros``).

Writes ``benchmarks/results/path_publication.{md,json}``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import RESULTS, machine_info, write_results

DEFAULT_POSES = (1000, 2000, 5000, 10000, 20000)


def publication_ms(n: int, repeats: int) -> dict[str, float]:
    """Median times [ms] of thinning ``2 n`` poses to ``n``, building the path and
    serialising it."""
    from lili_odom import geometry
    from lili_odom.bagio.writer import thin_poses
    from lili_odom.messages import path_of, pose_stamped_msg
    from lili_odom.ros.factory import RclpyFactory

    f = RclpyFactory()
    poses = [pose_stamped_msg(f, 100.0 + 0.1 * i,
                              geometry.exp(np.array([0.1 * i, 0.0, 0.0, 0.0, 0.0, 0.001 * i])),
                              "lili_odom") for i in range(2 * n)]
    build, serialise = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        msg = path_of(f, thin_poses(poses, n), "lili_odom", 100.0 + 0.2 * n)
        t1 = time.perf_counter()
        data = f.serialize(msg)
        t2 = time.perf_counter()
        build.append(t1 - t0)
        serialise.append(t2 - t1)
    return {"poses": n, "build_ms": 1e3 * float(np.median(build)),
            "serialise_ms": 1e3 * float(np.median(serialise)),
            "total_ms": 1e3 * float(np.median(np.add(build, serialise))),
            "bytes": len(data)}


def markdown(report: dict) -> str:
    m = report["machine"]
    lines = ["# One `~/path` publication by path length", "",
             "`python -m benchmarks.studies.path_publication` (module docstring): "
             "thinning twice as many poses, the `nav_msgs/Path` and its serialisation by "
             f"rclpy, median of {report['repeats']} repeats, on the node's processing thread. Machine: "
             f"{m['cpu']}, {m['cores']} cores, Python {m['python']}; commit `{m['commit']}`.",
             "",
             "| poses | build [ms] | serialise [ms] | total [ms] | message [kB] |",
             "|---:|---:|---:|---:|---:|"]
    for r in report["rows"]:
        lines.append(f"| {r['poses']} | {r['build_ms']:.1f} | {r['serialise_ms']:.1f} | "
                     f"{r['total_ms']:.1f} | {r['bytes'] / 1e3:.0f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, nargs="+", default=list(DEFAULT_POSES))
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    try:
        import rclpy.serialization  # noqa: F401
    except ImportError:
        raise SystemExit("path_publication: needs rclpy (make install-ros)") from None
    rows = [publication_ms(n, args.repeats) for n in args.poses]
    for r in rows:
        print(f"{r['poses']:6d} poses: {r['total_ms']:.1f} ms")
    report = {"machine": machine_info(), "repeats": args.repeats, "rows": rows}
    write_results(RESULTS, "path_publication", markdown(report), report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
