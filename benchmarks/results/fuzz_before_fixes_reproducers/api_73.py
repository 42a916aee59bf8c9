"""Fuzz finding: door api, seed 0, case 73: other_exception.

AttributeError: 'tuple' object has no attribute 'min'

Input: none; wheel covariance bad; times as a tuple, stamp -1.0, dropped 'x'

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 73))
