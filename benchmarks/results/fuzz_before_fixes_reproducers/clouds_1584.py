"""Fuzz finding: door clouds, seed 0, case 1584: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: xyzit 1x12 BE pad 0; time absolute times; data numpy float32; field x without offset; stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1584))
