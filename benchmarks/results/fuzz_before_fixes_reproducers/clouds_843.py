"""Fuzz finding: door clouds, seed 0, case 843: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyzit 4x15 BE pad 0; y = nan on 60/60 points; field y without datatype; stamp None

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 843))
