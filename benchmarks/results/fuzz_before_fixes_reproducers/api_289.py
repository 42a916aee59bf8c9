"""Fuzz finding: door api, seed 0, case 289: other_exception.

AttributeError: 'tuple' object has no attribute 'min'

Input: none; times as a tuple

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 289))
