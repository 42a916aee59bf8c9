"""Tunnel evaluation (the paper's Table II) into benchmarks/results/tunnel.{md,json,png}.

    python -m benchmarks.tunnel                      # Trials 1 and 2, full 128x1024, all methods
    python -m benchmarks.tunnel --resolution 64x512 --jobs 2

Bags are generated once into the simulator cache (data/sim or $LILI_ODOM_SIM_CACHE); per-run
outputs go to data/tunnel_runs. Any option of ``lili-odom evaluate`` is accepted.
"""
from __future__ import annotations

import sys

from benchmarks._common import RESULTS, ROOT
from lili_odom.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        args += ["--out", str(RESULTS)]
    if "--work-dir" not in args:
        args += ["--work-dir", str(ROOT / "data" / "tunnel_runs")]
    sys.exit(main(["evaluate", *args]))
