"""Fuzz finding: door clouds, seed 0, case 1088: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: ouster 1x33 BE pad 0; t reversed; field x without offset; is_bigendian True -> np.False_; stamp 1e+308

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1088))
