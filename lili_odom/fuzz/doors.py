"""The doors of the campaign and how one case of each is generated and run."""
from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from lili_odom.fuzz.outcome import Outcome

#: door name -> (stable id used in the case seed, module, per-case time limit [s])
DOORS: dict[str, tuple[int, str, float]] = {
    "clouds": (1, "lili_odom.fuzz.clouds", 30.0),
    "api": (2, "lili_odom.fuzz.api", 120.0),
    "feeder": (3, "lili_odom.fuzz.feeder", 120.0),
    "bags": (4, "lili_odom.fuzz.bags", 300.0),
    "sequences": (5, "lili_odom.fuzz.sequences", 900.0),
    "detect": (6, "lili_odom.fuzz.detect", 300.0),
    "selftest": (99, "lili_odom.fuzz.selftest", 5.0),
}


def case_rng(door: str, seed: int, index: int) -> np.random.Generator:
    """The generator of case ``index`` of ``door`` in the campaign ``seed``."""
    return np.random.default_rng([int(seed), DOORS[door][0], int(index)])


def run_case(door: str, seed: int, index: int, **options: Any) -> Outcome:
    """Generate and run one case (in this process: a native abort ends it)."""
    module = importlib.import_module(DOORS[door][1])
    return module.run_case(case_rng(door, seed, index), **options)
