"""Worker process of the campaign: runs cases of one door and reports each as a JSON line.

``python -m lili_odom.fuzz.worker DOOR SEED START STOP [OPTIONS_JSON]`` prints
``{"start": i}`` before case ``i`` and ``{"case": i, ...outcome}`` after it (flushed), so the
parent knows which case was running when the process died or stopped answering. These lines
go to the original standard output; everything else written to file descriptor 1 (Python
``print`` and native libraries alike) is sent to standard error.
"""
from __future__ import annotations

import json
import logging
import os
import sys
import time
import warnings


def main(argv: list[str]) -> int:
    from lili_odom.fuzz.doors import run_case

    door, seed, start, stop = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    options = json.loads(argv[4]) if len(argv) > 4 else {}
    logging.basicConfig(level=logging.CRITICAL)  # the cases log warnings by design
    warnings.simplefilter("ignore")
    out = os.fdopen(os.dup(1), "w", buffering=1)
    sys.stdout.flush()
    os.dup2(2, 1)  # native prints (e.g. Sophus) must not break the protocol
    for i in range(start, stop):
        out.write(json.dumps({"start": i}) + "\n")
        out.flush()
        t0 = time.perf_counter()
        outcome = run_case(door, seed, i, **options)
        row = {"case": i, "seconds": round(time.perf_counter() - t0, 4), **outcome.to_dict()}
        out.write(json.dumps(row) + "\n")
        out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
