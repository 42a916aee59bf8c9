"""Fuzz finding: door detect, seed 0, case 2: other_exception.

ValueError: 'x' must be finite, check for nan or inf values

Input: hessian; scan huge coordinates

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("detect", 0, 2))
