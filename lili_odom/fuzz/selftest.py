"""Door ``selftest``: cases that end in every way the campaign must tell apart.

The kind of a case is its generator's first draw ``rng.integers(6)``: 0 returns clean, 1 raises ``ValueError`` (documented here), 2 raises
``KeyError`` (undocumented), 3 aborts the process (``os.abort``, as a native assertion does),
4 sleeps past the time limit, 5 writes stray text to standard output (as native
libraries do) and returns clean. Used to test :mod:`lili_odom.fuzz.campaign` itself.
"""
from __future__ import annotations

import os
import time

import numpy as np

from lili_odom.fuzz.outcome import CLEAN, Outcome, from_exception


def run_case(rng: np.random.Generator, sleep_s: float = 60.0) -> Outcome:
    kind = int(rng.integers(6))
    try:
        if kind == 1:
            raise ValueError("documented")
        if kind == 2:
            raise KeyError("undocumented")
    except Exception as exc:  # noqa: BLE001
        return from_exception(exc, (ValueError,), f"kind {kind}")
    if kind == 3:
        os.abort()
    if kind == 4:
        time.sleep(sleep_s)
    if kind == 5:
        print("[stray] text on stdout", flush=True)
        os.write(1, b'{"not": "a protocol line"}\n[native] SO3::exp failed\n')
    return Outcome(CLEAN, "", f"kind {kind}")
