"""Fuzz finding: door api, seed 0, case 46: other_exception.

AttributeError: 'list' object has no attribute 'min'

Input: none; IMU stamp array([1., 2.]); points as a list, times as a list, dropped 'x'

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 46))
