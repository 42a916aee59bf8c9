"""Fuzz finding: door clouds, seed 0, case 154: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyzit 3x5 LE pad 0; y = 1e+19 on 2/15 points; field time without datatype; stamp 1e+308

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 154))
