"""Fuzz finding: door api, seed 0, case 189: other_exception.

TypeError: ufunc 'isfinite' not supported for the input types, and the inputs could not be safely coerced to any supported types according to the casting rule ''safe''

Input: none; points (3,), stamp 100.2; points float32, times alternating +-max, stamp b'1'

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 189))
