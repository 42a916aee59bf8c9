"""Fuzz finding: door api, seed 0, case 160: other_exception.

TypeError: '<' not supported between instances of 'complex' and 'float'

Input: none; times first -1e308, last +1e308, stamp (1+2j)

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 160))
