"""Clouds for a standalone detection, voxelised the way the odometry voxelises them.

The odometry hands its detector the scan as KISS-ICP registers it (deskewed, downsampled at
0.5 voxel then 1.5 voxel, evenly thinned to ``PipelineConfig.detection_points``) against a map
whose points were inserted at 0.5 voxel. :func:`prepare` does the same to a pair of clouds, so
``lili-odom detect`` answers for what the odometry would see, at the odometry's cost.

The voxel follows KISS-ICP's rule ``voxel = max_range / 100`` with the range the scan actually
reaches, capped at the odometry's ``scan_matcher.max_range``: a real sensor scan gets the
odometry's own voxel (1.0 m by default) and a small synthetic scene a proportionally finer one.
The reference map is a KISS-ICP voxel map like the odometry's, its voxel at least LiLi's
perturbation (``k - 1`` spacings of the downsampled reference) so that the 27-voxel neighbour
search reaches a perturbed scan's neighbours in a scene finer than the sensor's, and its
capacity the scan matcher's ``max_points_per_voxel`` or what keeps the reference's density in a
larger voxel. The detector is configured as in the odometry (:func:`odometry_detector`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from kiss_icp.voxelization import voxel_down_sample

from lili_odom.degeneracy.factory import raw_spacing, reference_for_detection
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.geometry import drop_nonfinite_rows


@dataclass
class DetectionInput:
    """What a detector is given.

    Attributes:
        reference: the reference map (reference frame).
        scan: (N, 3) scan points [m] in the scan frame, as handed to the detector.
        voxel_size: the odometry voxel [m] the clouds were downsampled with; None for raw clouds.
        scan_points_in / reference_points_in: finite points before downsampling.
    """

    reference: ReferenceMap
    scan: np.ndarray
    voxel_size: float | None
    scan_points_in: int
    reference_points_in: int


def odometry_voxel_size(scan: np.ndarray, max_range: float = 100.0) -> float:
    """KISS-ICP's voxel rule [m]: ``min(max_range, farthest scan point) / 100``."""
    ranges = np.linalg.norm(np.asarray(scan, dtype=float), axis=1)
    reach = float(ranges.max()) if len(ranges) else 0.0
    if not np.isfinite(reach) or reach <= 0:
        raise ValueError("scan has no point away from the sensor origin")
    return min(float(max_range), reach) / 100.0


def thin_evenly(points: np.ndarray, count: int) -> np.ndarray:
    """Every k-th point so that at most ``count`` remain (``count`` 0 keeps all)."""
    if count and len(points) > count:
        return points[:: int(np.ceil(len(points) / count))]
    return points


def prepare(reference: np.ndarray, scan: np.ndarray, *, raw: bool = False,
            voxel_size: float | None = None, max_range: float | None = None,
            detection_points: int | None = None) -> DetectionInput:
    """Reference map and scan for a detection.

    Args:
        reference: (M, 3) reference points [m], reference frame.
        scan: (N, 3) scan points [m], scan frame (sensor at the origin).
        raw: keep every point; ``voxel_size`` is then the reference map's voxel (default: 10
            reference spacings, :func:`reference_for_detection`).
        voxel_size: the odometry voxel [m] (default :func:`odometry_voxel_size`).
        max_range: range cap of the voxel rule [m] (default the odometry's
            ``scan_matcher.max_range``).
        detection_points: scan points kept after downsampling (default the odometry's
            ``detection_points``; 0 keeps all).

    Raises:
        ValueError: a cloud is empty, non-finite throughout or too small to size a map.
    """
    from lili_odom.pipeline.odometry import PipelineConfig

    defaults = PipelineConfig()
    reference = drop_nonfinite_rows(np.asarray(reference, dtype=np.float64).reshape(-1, 3))
    scan = drop_nonfinite_rows(np.asarray(scan, dtype=np.float64).reshape(-1, 3))
    if len(scan) == 0 or len(reference) == 0:
        raise ValueError("a cloud has no finite point")
    if raw:
        return DetectionInput(reference_for_detection(reference, voxel_size), scan, None,
                              len(scan), len(reference))
    if voxel_size is None:
        cap = defaults.scan_matcher.max_range if max_range is None else max_range
        voxel_size = odometry_voxel_size(scan, cap)
    if not voxel_size > 0:
        raise ValueError(f"voxel size must be > 0 m, got {voxel_size}")
    count = defaults.detection_points if detection_points is None else detection_points
    map_points = np.asarray(voxel_down_sample(reference, 0.5 * voxel_size))
    source = np.asarray(voxel_down_sample(np.asarray(voxel_down_sample(scan, 0.5 * voxel_size)),
                                          1.5 * voxel_size))
    spacing = raw_spacing(map_points)
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError("reference cloud too small or degenerate to size a voxel map")
    map_voxel = max(float(voxel_size), (defaults.lili.k - 1) * spacing)
    capacity = max(defaults.scan_matcher.max_points_per_voxel,
                   int(np.ceil(2.0 * (map_voxel / spacing) ** 2)))
    ref_map = ReferenceMap.from_points(map_points, map_voxel, capacity)
    return DetectionInput(ref_map, thin_evenly(source, count), float(voxel_size), len(scan),
                          len(reference))


def odometry_detector(method: str):
    """The detector ``method`` configured as the odometry runs it (``PipelineConfig``)."""
    from lili_odom.pipeline.odometry import PipelineConfig, make_detector

    detector = make_detector(PipelineConfig(method=method))
    if detector is None:
        raise ValueError(f"no detector for method {method!r}")
    return detector
