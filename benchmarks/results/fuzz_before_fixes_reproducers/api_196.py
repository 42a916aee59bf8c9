"""Fuzz finding: door api, seed 0, case 196: other_exception.

TypeError: can only concatenate list (not "float") to list

Input: none; wheel covariance bad; times random over float64, stamp [100.35]

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 196))
