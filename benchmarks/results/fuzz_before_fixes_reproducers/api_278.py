"""Fuzz finding: door api, seed 0, case 278: other_exception.

AttributeError: 'list' object has no attribute 'min'

Input: none; wheel pose teleport; times as a list, stamp -1.7976931348623157e+308

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 278))
