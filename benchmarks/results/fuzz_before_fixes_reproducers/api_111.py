"""Fuzz finding: door api, seed 0, case 111: other_exception.

ValueError: cannot reshape array of size 1 into shape (3)

Input: none; IMU saturated; wheel pose array([[0., 0., 0., 0.], [0., 0., 0.,...; points None, stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 111))
