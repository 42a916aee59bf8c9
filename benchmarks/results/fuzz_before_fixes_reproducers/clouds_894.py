"""Fuzz finding: door clouds, seed 0, case 894: other_exception.

AttributeError: 'types.SimpleNamespace' object has no attribute 'offset'

Input: ouster 1x11 LE pad 0; t random over the whole range; x = nan on 11/11 points; field intensity without offset; stamp inf

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("clouds", 0, 894))
