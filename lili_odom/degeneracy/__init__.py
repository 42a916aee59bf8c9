"""Degeneracy detectors for scan-to-map alignment: LiLi (perturbation/Lie) and Zhang (Hessian)."""
from lili_odom.degeneracy.result import DegeneracyResult

__all__ = ["DegeneracyResult"]
