"""Fuzz finding: door bags, seed 0, case 36: other_exception.

GeometryException: Degenerate covariance rank, Umeyama alignment is not possible

Input: zeroed block in the first chunks

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("bags", 0, 36))
