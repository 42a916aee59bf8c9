"""Fuzz finding: door clouds, seed 0, case 707: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyzit 1x46 LE pad 0; time absolute times; field intensity without datatype; stamp 1700000000.0

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 707))
