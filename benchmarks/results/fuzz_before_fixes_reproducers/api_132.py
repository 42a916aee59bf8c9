"""Fuzz finding: door api, seed 0, case 132: other_exception.

ValueError: The truth value of an array with more than one element is ambiguous. Use a.any() or a.all()

Input: none; constant times, stamp 1e+308; times (N, 1), stamp array([1., 2.])

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 132))
