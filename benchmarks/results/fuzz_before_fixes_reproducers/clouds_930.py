"""Fuzz finding: door clouds, seed 0, case 930: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyz64_ns 1x5 LE pad 0; x = -inf on 2/5 points; z = 0 on 5/5 points; field z without datatype; stamp 1e+308

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 930))
