"""Fuzz finding: door clouds, seed 0, case 957: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: ouster 4x31 LE pad 0; x = 3.40282e+38 on 55/124 points; field range without datatype; all fields at offset 0; stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 957))
