"""Fuzz finding: door api, seed 0, case 296: other_exception.

ValueError: cannot reshape array of size 1 into shape (3)

Input: none; points None, times 1e308 for fewer than 2 points

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 296))
