"""Fuzz finding: door api, seed 0, case 25: other_exception.

TypeError: '<' not supported between instances of 'complex' and 'float'

Input: none; non-finite times; IMU gyro array([1.e+308, 1.e+308, 1.e+308]); points (N, 4), stamp (1+2j)

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 25))
