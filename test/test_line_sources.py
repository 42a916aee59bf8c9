"""The line-sources study places line centroids against a world's objects correctly."""
import numpy as np

from benchmarks.studies.line_sources import classify, footprints
from lili_odom.sim.world import load_world


def test_footprints_of_the_airfield():
    axes, boxes = footprints(load_world("airfield"))
    assert len(axes) == 4  # the four masts
    assert np.allclose(sorted(axes[:, 0]), [5.0, 50.0, 80.0, 85.0])
    hangar = next(b for b in boxes if np.allclose(b.mean(axis=0), [-30.0, -30.0]))
    assert np.allclose(np.ptp(hangar, axis=0), [30.0, 40.0])  # yaw 0: x and y extents


def test_classify_pole_corner_face_other():
    axes = np.array([[0.0, 0.0]])
    box = np.array([[10.0, 10.0], [10.0, -10.0], [20.0, -10.0], [20.0, 10.0]])
    points = np.array([[0.3, 0.2],      # beside the pole
                       [10.5, 10.4],    # at a corner of the box
                       [10.4, 0.0],     # on a face, far from the corners
                       [50.0, 50.0]])   # nothing near
    counts = classify(points, axes, [box], pole=1.0, corner=1.5, face=1.0)
    assert counts == {"pole": 1, "corner": 1, "flat face": 1, "other": 1}
