"""Fuzz finding: door api, seed 0, case 287: native_abort.

SIGABRT: [/project/python/build/cp311-cp311-linux_x86_64/_deps/sophus-src/sophus/so3.hpp:747] SOPHUS_ENSURE failed: SO3::exp failed! omega: -nan -nan -nan, real: -nan, img: -nan

Input: 

Run from the repository root: python <this file> (a native abort ends it with a signal).
"""
import os
import sys

sys.path.insert(0, os.getcwd())

from lili_odom.fuzz.doors import run_case  # noqa: E402

print(run_case("api", 0, 287))
