"""Fuzz finding: door clouds, seed 0, case 1228: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: ouster 1x11 LE pad 0; t reversed; z = -3.40282e+38 on 11/11 points; field intensity without offset; stamp inf

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1228))
