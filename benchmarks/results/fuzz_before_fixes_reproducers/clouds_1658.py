"""Fuzz finding: door clouds, seed 0, case 1658: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'datatype'

Input: xyz 2x20 LE pad 0; height 2 -> 1099511627776; field y without datatype; stamp 1700000000.0

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 1658))
