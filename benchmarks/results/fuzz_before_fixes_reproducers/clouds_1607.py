"""Fuzz finding: door clouds, seed 0, case 1607: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: xyz_i16_padded 1x58 LE pad 0; y = -3.40282e+38 on 1/58 points; data bytearray; field x without offset; stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1607))
