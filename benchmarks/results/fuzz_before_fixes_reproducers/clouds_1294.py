"""Fuzz finding: door clouds, seed 0, case 1294: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: xyz 1x37 LE pad 0; field z without offset; point_step 12 -> nan; data numpy float32; stamp 1700000000.0

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1294))
