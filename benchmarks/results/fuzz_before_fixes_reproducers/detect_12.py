"""Fuzz finding: door detect, seed 0, case 12: other_exception.

IndexError: index 574 is out of bounds for axis 0 with size 574

Input: hessian; reference huge coordinates

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("detect", 0, 12))
