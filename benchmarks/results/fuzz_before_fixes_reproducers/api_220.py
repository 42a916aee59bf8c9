"""Fuzz finding: door api, seed 0, case 220: other_exception.

TypeError: ufunc 'isfinite' not supported for the input types, and the inputs could not be safely coerced to any supported types according to the casting rule ''safe''

Input: lili; points (N, 4), stamp <object object at 0x7f9ac434e720>

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 220))
