"""Fuzz finding: door clouds, seed 0, case 792: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: xyz_i16_padded 2x45 LE pad 0; x = nan on 90/90 points; field y without offset; stamp 0.0

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 792))
