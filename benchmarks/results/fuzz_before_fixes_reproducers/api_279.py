"""Fuzz finding: door api, seed 0, case 279: other_exception.

TypeError: ufunc 'isfinite' not supported for the input types, and the inputs could not be safely coerced to any supported types according to the casting rule ''safe''

Input: none; IMU saturated; times alternating +-max, stamp <object object at 0x7f62115a6720>

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 279))
