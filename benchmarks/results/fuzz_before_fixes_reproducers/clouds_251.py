"""Fuzz finding: door clouds, seed 0, case 251: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: ouster 1x35 LE pad 0; t random over the whole range; width 35 -> -1; field t without offset; stamp nan

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 251))
