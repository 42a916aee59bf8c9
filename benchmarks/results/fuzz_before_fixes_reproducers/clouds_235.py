"""Fuzz finding: door clouds, seed 0, case 235: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: ouster 1x12 LE pad 0; z = -inf on 12/12 points; t one time at max; field ring without datatype; stamp None

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 235))
