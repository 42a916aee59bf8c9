"""Fuzz finding: door api, seed 0, case 285: other_exception.

TypeError: can only concatenate str (not "int") to str

Input: none; non-finite points, non-finite times, dropped 'x'

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 285))
