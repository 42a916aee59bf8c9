"""Fuzz finding: door clouds, seed 0, case 741: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyzit 1x50 BE pad 0; field time without datatype; drop field x; stamp 0.0

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 741))
