"""Fuzz finding: door api, seed 0, case 244: other_exception.

TypeError: '<' not supported between instances of 'complex' and 'float'

Input: none; IMU gyro [0.0, 0.0, 9.8]; times complex, stamp (1+2j), dropped 'x'

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 244))
