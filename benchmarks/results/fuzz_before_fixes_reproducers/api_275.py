"""Fuzz finding: door api, seed 0, case 275: other_exception.

ValueError: cannot reshape array of size 1 into shape (3)

Input: none; wheel pose teleport; IMU stamp True; points None, times 1e308 for fewer than 2 points, stamp array([1., 2.])

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 275))
