"""Fuzz finding: door clouds, seed 0, case 1203: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyz 1x32 LE pad 2; y = 0 on 0/32 points; field y without datatype; data object; stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1203))
