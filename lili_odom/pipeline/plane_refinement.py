"""Point-to-plane refinement of a registration inside its detected degenerate subspace.

A direction LiLi flags (point-to-point ICP does not come back along it) is not necessarily
one the scene says nothing about: in a corridor whose end walls are within range, or past a
few door recesses, the points on surfaces facing the axis fix the position along it to
centimetres, while the many points on the side walls, floor and ceiling (whose point-to-point
residuals have a tangential part) hold a perturbed point-to-point registration where it was
put. This module measures what the LiDAR does know along the detected subspace:

1. start from the registration whose degenerate components are the prediction's (solution
   remapping, :mod:`lili_odom.pipeline.remap`);
2. associate each scan point with its ``normal_neighbors`` nearest local-map points (scipy
   ``cKDTree`` of the map KISS-ICP keeps), fit a plane to them by PCA (normal = eigenvector of
   the smallest eigenvalue) and form the point-to-plane residual ``r = n . (T p - c)``; where
   the neighbours form a near-vertical line instead (a pole, a trunk) and ``vertical_lines``
   is on, the point gets two residuals on planes through the line, one per direction across
   it;
3. take a few damped Gauss-Newton steps on those planes in the subspace coordinates ``c``
   only (``T exp(S^-1 B^T c)``); the other components stay at the registration's optimum;
4. report the Gauss-Newton information of the subspace coordinates at the result,
   ``H = sum w_i J_i^T J_i / sigma^2`` with ``J_i = [n_b, p x n_b] S^-1 B^T``, where
   ``sigma`` is the robust scatter of the residuals (floored at ``min_point_sigma``) and the
   sum is scaled by ``independent_fraction`` (neighbouring residuals share the map's and the
   scan's errors, so they are not independent measurements).

In a featureless tube or between two parallel walls the normals are perpendicular to the
axis, ``H`` is about zero and the fusion leaves the axis to the wheels and the IMU; with end
walls in range ``H`` is large and the LiDAR keeps holding the axis.

This is not a registration of its own: KISS-ICP's point-to-point ICP remains the
registration, and the refinement only moves the pose inside the (usually one-dimensional)
subspace it could not fix.

Frames and units: scan points (N, 3) in the LiDAR frame [m]; poses ``T_odom_lidar`` 4x4 [m];
``basis_scaled`` rows are scaled LiDAR body twists ``(v, L w)`` (:mod:`lili_odom.degeneracy.result`);
the returned information is (k, k) over the subspace coordinates ``c`` [1/m^2] and
(6, 6) over scaled LiDAR body twists ``(v, L w)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.reference import ReferenceMap, kdtree_workers
from lili_odom.degeneracy.subspace import orthonormal_rows

__all__ = ["PlaneFitCache", "PlaneFits", "PlaneRefinementConfig", "PlaneRefinement", "eigenvector3",
           "fit_planes", "plane_cost", "plane_jacobians", "refine_in_subspace",
           "returned_directions", "without_unheld"]


#: Information [1/m^2] (a 1 m sigma) below which :func:`returned_directions` does not test a
#: direction.
MIN_TESTED_INFORMATION = 1.0

#: Values of ``PlaneRefinementConfig.return_check``.
RETURN_CHECKS = ("off", "prediction", "bounded", "offset")
#: Values of ``PlaneRefinementConfig.screened_subspace_remap``.
SCREENED_SUBSPACE_REMAPS = ("registration", "off")

#: Values of ``PlaneRefinementConfig.refine_constrained``.
REFINE_CONSTRAINED = ("off", "all", "planar")


@dataclass
class PlaneRefinementConfig:
    """Attributes:
        enabled: refine degenerate registrations in their subspace and give the fusion the
            LiDAR's information there (False: the subspace is left to wheels and IMU).
        iterations: Gauss-Newton steps on the planes found at the start pose; default 3.
        points: scan points used (evenly thinned from the 0.5-voxel frame); default 4000.
        normal_neighbors: local-map points per plane fit (PCA); default 10.
        max_neighbor_distance: a plane fit whose farthest neighbour is farther than this from
            the point is not used [m]; default 1.5.
        min_planarity: plane fits with ``(l2 - l3) / l1`` below this (eigenvalues of the
            neighbourhood covariance, descending) are not used (dimensionless); default 0.3.
        max_residual: correspondences with a point-to-plane residual above this are not used
            [m]; default 0.3.
        kernel: Cauchy kernel width on the residuals [m]; default 0.05.
        min_point_sigma: floor of the residual 1-sigma used for the information [m];
            default 0.03.
        independent_fraction: fraction of the used points counted as independent
            measurements in the information (0..1); default 0.05.
        max_step: largest Gauss-Newton step in the subspace [m, scaled]; default 0.3.
        debias: subtract the expected contribution of the plane fits' normal noise from the
            information (``_debiased``); default True.
        along_track: refine the registration along its direction of travel (the predicted
            translation since the previous scan, outside the detected subspace): with
            at least ``min_along_information`` the refined pose is the LiDAR measurement,
            else the direction of travel is taken as degenerate
            (:meth:`lili_odom.pipeline.odometry.OdometryPipeline._along_track`). Default True.
        min_travel_m: predicted travel since the previous scan below which there is no
            along-track refinement [m]; default 0.01.
        min_along_share: on a degenerate scan, the along-track refinement covers the part of
            the direction of travel outside the detected subspace when that part's norm is at
            least this (unit direction, scaled twists); default 0.5.
        weak_information: directions of base_link's forward, lateral and yaw motion outside
            the detected subspace along which the registration's point-to-plane information
            (debiased, scaled twists) is below this [1/m^2] join the subspace
            (:meth:`lili_odom.pipeline.odometry.OdometryPipeline._weak_directions`); default
            1000 (a 3 cm sigma); 0 = never.
        min_along_information: information [1/m^2] along the direction of travel from which
            the along-track refinement counts as holding it (default 100: a 10 cm sigma).
        refine_constrained: after the checks above, refine the registration by point-to-plane
            in the directions outside the degenerate subspace that it holds with at least
            ``constrained_information`` (the planes of the checks, no extra nearest-neighbour
            query): ``off``, ``all`` (every such direction) or ``planar`` (only base_link's
            forward, lateral and yaw motion; default).
        constrained_information: information [1/m^2] from which a direction outside the
            degenerate subspace takes the point-to-plane refinement's step
            (``refine_constrained``); along the others the registration's pose stays.
            Default 1000 (a 3 cm sigma, as ``weak_information``).
        constrained_rounds: rounds of the constrained refinement (``refine_constrained``)
            on a scan the screen found held in every direction (``screen_detections``; other
            scans get one), each starting where the last one ended, on planes found again
            there once it is more than 5 cm or 0.002 rad from where they were found; the
            rounds end early when one moves the pose less than ``constrained_settle_m``.
            Default 4; 1 = one round on the planes found at the registration. Where the
            registration sits centimetres off (a young map's scan pattern holding it back
            while the robot accelerates), one round on planes gated at that pose takes only
            part of the way back.
        constrained_settle_m: translation [m] below which a round of the constrained
            refinement ends the rounds; default 0.02.
        constrained_from_prediction: on such a scan also run the rounds from the motion
            prediction (IMU and wheels from the last fused state) and keep whichever result
            fits the planes found at the first result better (``plane_cost``, over every
            plane, so the prediction's height and tilt are scored too). Meant for a
            registration whose rounds settle behind the robot (a young map's scan pattern
            while it accelerates from rest), where the prediction may start beyond that
            minimum. Default false.
        clear_information: a detected direction along which the refinement's information is
            at least this [1/m^2] is measured by the refined pose like a constrained one and
            removed from the degenerate subspace (default 1000: a 3 cm sigma, as
            ``weak_information``); 0 = never.
        held_information: a direction of the degenerate subspace along which the
            refinement's information is at least this [1/m^2] is reported as weakly
            constrained rather than degenerate (``OdometryOutput.weak_basis``, not
            ``degenerate_basis``): the LiDAR holds it, and the fusion takes it with that
            weight either way, so this only sets what the outputs call degenerate. Default
            30 (an 18 cm sigma), the bar of ``screen_weak_information``: a direction the
            planes hold well enough to skip the detector is not called degenerate either;
            1e12: every direction of the subspace is reported as degenerate.
        information_without_wheels: factor on the subspace information the fusion gets
            from the refinement on a scan without wheel data (dimensionless, 0..1); default
            1 (the measured information). Below 1 the fusion leans on the IMU along weakly
            held directions during a wheel outage or without wheels.
        screen_detections: skip the degeneracy detector on a scan whose registration the
            planes hold in every direction with at least ``clear_information`` (the debiased
            point-to-plane information over all six scaled twists, from the planes the checks
            use anyway): such a scan counts as constrained, since every direction a detection
            could flag there would be cleared again. Default True; False runs the detector
            (or carries a detection over) on every scan.
        screen_weak_information: a scan whose planes hold every direction with at least
            this information [1/m^2], but some with less than ``clear_information``, does not
            run the detector either (``screen_detections``): its degenerate subspace is the
            directions the planes hold with less than ``clear_information`` (eigenvectors of
            the screen's information), each then held with its own information like a
            detected one (``held_information``). The detector is asked only where the planes
            leave some direction nearly free. 0 = never (the detector decides every scan the
            screen does not pass). Default 30 (an 18 cm sigma; ``docs/performance.md``,
            "Planes that hold every direction").
        screened_subspace_remap: the solution remapping on a scan whose screen gave the
            planes' subspace (``screen_weak_information``), before the refinement inside it:
            ``registration`` (default; as on a detected subspace: the registration run again
            held at the wheels' prediction along the subspace) or ``off`` (the refinement
            starts at the registration).
        check_screened_subspace: the weak-direction and along-track checks
            (``weak_information``, ``along_track``) on a scan whose screen gave the planes'
            subspace. False skips them: every direction outside that subspace is held with
            at least ``clear_information``, which is what they test, and the constrained
            refinement takes the step there. Default True.
        weigh_registration: the fusion weighs a scan's registration by the screen's
            point-to-plane information too, on scans where the screen ran: the covariance
            of the configured LiDAR sigmas (``fusion.lidar``) plus the planes'
            (:func:`lili_odom.fusion.measurements.registration_information`), so a scan its
            planes hold weakly counts for less against the IMU. False: the configured
            sigmas alone. Default False.
        predicted_start: without wheel data, the refinement inside the subspace is also run
            from the fused prediction's components there and kept when it fits the planes
            better and they hold every direction of the subspace to
            ``min_along_information``; default True.
        return_check: on scans without wheel data, test whether the planes hold the
            directions whose information the fusion gets, the way LiLi tests a registration
            (moved, re-associated, does it come back): ``prediction`` (default; acts with
            ``predicted_start``): where the refinement from the prediction is not kept, the
            direction from the registration to the prediction loses its information unless
            that refinement came back to the registration's by ``max_return_ratio`` of the
            distance (no extra plane fits); ``bounded``: as ``prediction``, but such a
            direction keeps at most ``1 / d^2`` of information, ``d`` how far apart the two
            refinements ended along it [m, scaled] (the planes place the scan no better than
            that, and without wheels over a long stretch it is all that holds the
            direction); ``offset``: every direction of the subspace with
            information is moved by ``return_offset`` from the result, on planes found again
            there (:func:`returned_directions`); ``off``. Planes fitted across a sparse
            scan's rings on a curved wall tilt with the sampling pattern: they claim
            information wherever the scan is put, and hold a point-to-point registration's
            lag behind the motion.
        return_check_window_s: the return check runs only on scans within this many seconds
            of the newest wheel data [s]: a direction it takes from the LiDAR is left to the
            IMU, which carries it only while its calibration against the wheels is recent;
            without wheel data for longer, or ever, the LiDAR keeps its information (on open
            ground it is all that holds the direction of travel). Default 30.
        return_offset: how far the ``offset`` return check moves the result [m, scaled
            twist: a rotation of ``return_offset / L`` rad]; default 0.1 (the 10 cm sigma
            of ``min_along_information``).
        max_return_ratio: the share of the distance moved (the offset, or the registration
            to the prediction) a refinement must come back by for the direction to count as
            held (dimensionless, 0..1); default 0.5.
        vertical_lines: a neighbourhood that is not planar but a near-vertical line (a pole,
            a trunk, a thin mast) is used too, as two planes through the line: it holds the
            point across the line, horizontally (``_lines``). Default False: the
            line through the neighbours' centroid lies on the side of a pole earlier scans
            saw, up to its radius off the side this scan sees.
        vertical_lines_without_wheels: use vertical lines (as ``vertical_lines``) on scans
            with no wheel data for longer than ``return_check_window_s``, or none at all:
            there poles, masts and pipes are much of what holds the directions of planar
            motion against the IMU, while with wheels, or in a short outage after them, their
            offset costs more than they add. Default True.
        min_linearity: neighbourhoods with ``(l1 - l2) / l1`` at least this are lines
            (dimensionless); default 0.8.
        max_line_tilt_deg: lines tilted from the vertical by more than this are not used
            [deg] (a ring of a sparse scan on the ground or on a wall is a horizontal line
            that moves with the sensor); default 20.
        line_neighbors: a line is used only if this many nearest local-map points of the
            scan point (those within ``max_neighbor_distance``, at least
            ``normal_neighbors``) form a near-vertical line too (``min_linearity``,
            ``max_line_tilt_deg``); where they form a plane (``min_planarity``) the point
            gets that plane instead. A sparse sensor driving towards a wall leaves vertical
            strips of points at its columns' bearings: the few nearest points of one strip
            look like a pole, while the wall's plane runs across it. 0 = no such check.
            Default 30.
        blobs: a neighbourhood that is neither planar, nor a line of any direction
            (``min_linearity``), but spread in every direction (``min_sphericity``) - a
            corner, a recess's edge seen across, a lamp - holds the point by its spread: up
            to three residuals through its centroid along its principal axes (those
            ``max_blob_spread`` keeps), each weighted by
            ``min_point_sigma / sqrt(l_i + min_point_sigma^2)`` (``l_i`` the axis's variance
            [m^2]; generalised ICP's point-to-distribution distance). Default False.
        blobs_without_wheels: use such neighbourhoods (as ``blobs``) on scans with no wheel
            data for longer than ``return_check_window_s``, or none at all (as
            ``vertical_lines_without_wheels``). Default False.
        min_sphericity: a neighbourhood counts for ``blobs`` when its smallest covariance
            eigenvalue is at least this share of its largest (dimensionless); default 0.05.
        max_blob_spread: a blob's axis is used only where the neighbourhood's variance along
            it is at most this share of the squared distance to its farthest neighbour
            (dimensionless): along an axis where the neighbours reach as far as the search did
            (about 0.2-0.33 of that square for a cut-off ball, disc or segment), the search
            cut the structure off and the centroid follows the point. Default 0.1; 1 = every
            axis.
    """

    enabled: bool = True
    iterations: int = 3
    points: int = 4000
    normal_neighbors: int = 10
    max_neighbor_distance: float = 1.5
    min_planarity: float = 0.3
    max_residual: float = 0.3
    kernel: float = 0.05
    min_point_sigma: float = 0.03
    independent_fraction: float = 0.05
    max_step: float = 0.3
    debias: bool = True
    along_track: bool = True
    min_travel_m: float = 0.01
    min_along_share: float = 0.5
    weak_information: float = 1000.0
    min_along_information: float = 100.0
    clear_information: float = 1000.0
    held_information: float = 30.0
    information_without_wheels: float = 1.0
    refine_constrained: str = "planar"
    constrained_information: float = 1000.0
    constrained_rounds: int = 4
    constrained_settle_m: float = 0.02
    constrained_from_prediction: bool = False
    screen_detections: bool = True
    screen_weak_information: float = 30.0
    screened_subspace_remap: str = "registration"
    check_screened_subspace: bool = True
    weigh_registration: bool = False
    predicted_start: bool = True
    return_check: str = "prediction"
    return_check_window_s: float = 30.0
    return_offset: float = 0.1
    max_return_ratio: float = 0.5
    vertical_lines: bool = False
    vertical_lines_without_wheels: bool = True
    min_linearity: float = 0.8
    max_line_tilt_deg: float = 20.0
    line_neighbors: int = 30
    blobs: bool = False
    blobs_without_wheels: bool = False
    min_sphericity: float = 0.05
    max_blob_spread: float = 0.1

    def validate(self, prefix: str = "plane_refinement.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        from lili_odom.errors import check_range

        check_range(prefix + "iterations", self.iterations, 0, 100)
        check_range(prefix + "points", self.points, 10, 10_000_000)
        check_range(prefix + "normal_neighbors", self.normal_neighbors, 3, 100)
        check_range(prefix + "max_neighbor_distance", self.max_neighbor_distance, 0.0, 100.0,
                    lo_open=True, unit="m")
        check_range(prefix + "min_planarity", self.min_planarity, 0.0, 1.0)
        check_range(prefix + "max_residual", self.max_residual, 0.0, 100.0, lo_open=True,
                    unit="m")
        check_range(prefix + "kernel", self.kernel, 0.0, 100.0, lo_open=True, unit="m")
        check_range(prefix + "min_point_sigma", self.min_point_sigma, 0.0, 10.0, lo_open=True,
                    unit="m")
        check_range(prefix + "independent_fraction", self.independent_fraction, 0.0, 1.0,
                    lo_open=True)
        check_range(prefix + "max_step", self.max_step, 0.0, 100.0, lo_open=True, unit="m")
        check_range(prefix + "min_travel_m", self.min_travel_m, 0.0, 100.0, unit="m")
        check_range(prefix + "min_along_share", self.min_along_share, 0.0, 1.0)
        check_range(prefix + "weak_information", self.weak_information, 0.0, 1e12)
        check_range(prefix + "min_along_information", self.min_along_information, 0.0, 1e12)
        check_range(prefix + "clear_information", self.clear_information, 0.0, 1e12)
        check_range(prefix + "held_information", self.held_information, 0.0, None)
        check_range(prefix + "screen_weak_information", self.screen_weak_information, 0.0,
                    1e12)
        check_range(prefix + "information_without_wheels", self.information_without_wheels,
                    0.0, 1.0)
        check_range(prefix + "constrained_information", self.constrained_information, 0.0,
                    1e12, lo_open=True)
        check_range(prefix + "constrained_rounds", self.constrained_rounds, 1, 100)
        check_range(prefix + "constrained_settle_m", self.constrained_settle_m, 0.0, 10.0,
                    unit="m")
        check_range(prefix + "return_check_window_s", self.return_check_window_s, 0.0, None,
                    unit="s")
        check_range(prefix + "return_offset", self.return_offset, 0.0, 10.0, lo_open=True,
                    unit="m")
        check_range(prefix + "max_return_ratio", self.max_return_ratio, 0.0, 1.0)
        check_range(prefix + "min_linearity", self.min_linearity, 0.0, 1.0)
        check_range(prefix + "max_line_tilt_deg", self.max_line_tilt_deg, 0.0, 90.0, unit="deg")
        check_range(prefix + "line_neighbors", self.line_neighbors, 0, 1000)
        check_range(prefix + "min_sphericity", self.min_sphericity, 0.0, 1.0)
        check_range(prefix + "max_blob_spread", self.max_blob_spread, 0.0, 1.0)
        if self.screened_subspace_remap not in SCREENED_SUBSPACE_REMAPS:
            raise ValueError(f"{prefix}screened_subspace_remap must be one of "
                             f"{', '.join(SCREENED_SUBSPACE_REMAPS)}, got "
                             f"'{self.screened_subspace_remap}'")
        if self.return_check not in RETURN_CHECKS:
            raise ValueError(f"{prefix}return_check must be one of "
                             f"{', '.join(RETURN_CHECKS)}, got '{self.return_check}'")
        if self.refine_constrained not in REFINE_CONSTRAINED:
            raise ValueError(f"{prefix}refine_constrained must be one of "
                             f"{', '.join(REFINE_CONSTRAINED)}, got '{self.refine_constrained}'")


@dataclass
class PlaneRefinement:
    """Attributes:
        pose: 4x4 refined ``T_odom_lidar`` (the input pose moved inside the subspace).
        information: (k, k) information of the subspace coordinates [1/m^2].
        information_scaled: (6, 6) the same over scaled LiDAR body twists (supported on the
            subspace).
        basis_scaled: (k, 6) orthonormal subspace rows the coordinates refer to.
        points_used: correspondences in the last information.
        sigma: residual 1-sigma used [m].
        ok: False when too few correspondences were found (pose = the input, information 0).
    """

    pose: np.ndarray
    information: np.ndarray
    information_scaled: np.ndarray
    basis_scaled: np.ndarray
    points_used: int = 0
    sigma: float = float("nan")
    ok: bool = True
    details: dict = field(default_factory=dict)


def plane_jacobians(points: np.ndarray, normals_body: np.ndarray) -> np.ndarray:
    """(N, 6) derivatives of point-to-plane residuals by a body twist ``(v, w)`` of the pose.

    ``r(xi) = n . (T exp(xi) p - c)``; with ``n_b = R^T n`` (the normal in the body frame)
    ``dr/dxi = [n_b, p x n_b]``.
    """
    return np.hstack([normals_body, np.cross(points, normals_body)])


def symmetric_eigen3(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (m, 3), ascending, of symmetric 3x3 matrices ``A`` (m, 3, 3) and the unit
    eigenvector (m, 3) of the smallest, in closed form (the trigonometric solution of the
    characteristic cubic; the vector as the largest cross product of two rows of
    ``A - l_min I``). Several times faster than ``np.linalg.eigh`` on many small matrices;
    the vector is exact where ``l_min`` is separated from the middle eigenvalue (a plane),
    arbitrary where it is not (a line or a blob: check the eigenvalues)."""
    A = np.asarray(A, dtype=float)
    a00, a11, a22 = A[:, 0, 0], A[:, 1, 1], A[:, 2, 2]
    a01, a02, a12 = A[:, 0, 1], A[:, 0, 2], A[:, 1, 2]
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p = np.sqrt(np.maximum(b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1, 0.0) / 6.0)
    safe = np.where(p > 0, p, 1.0)
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
           + a02 * (a01 * a12 - b11 * a02)) / safe**3
    phi = np.arccos(np.clip(0.5 * det, -1.0, 1.0)) / 3.0
    l_max = q + 2.0 * p * np.cos(phi)
    l_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    w = np.stack([l_min, 3.0 * q - l_max - l_min, l_max], axis=1)
    return w, eigenvector3(A, l_min)


def eigenvector3(A: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Unit eigenvectors (m, 3) of symmetric 3x3 matrices ``A`` (m, 3, 3) for their simple
    eigenvalues ``lam`` (m,): the largest cross product of two rows of ``A - lam I`` (sign
    arbitrary; +z where ``A - lam I`` has rank below 2)."""
    M = A - lam[:, None, None] * np.eye(3)
    r0, r1, r2 = M[:, 0], M[:, 1], M[:, 2]
    c = np.stack([np.cross(r0, r1), np.cross(r0, r2), np.cross(r1, r2)], axis=1)  # (m, 3, 3)
    n2 = np.einsum("mij,mij->mi", c, c)
    best = np.argmax(n2, axis=1)
    v = c[np.arange(len(A)), best]
    norm = np.sqrt(n2[np.arange(len(A)), best])
    return np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None],
                    np.array([0.0, 0.0, 1.0]))


def _covariances(d: np.ndarray) -> np.ndarray:
    """(m, 3, 3) covariances of ``m`` neighbourhoods of centred points ``d`` (m, k, 3): the six
    distinct entries as sums over the neighbours (faster than batched 3 x k products)."""
    m, k = d.shape[:2]
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    cov = np.empty((m, 3, 3))
    for i, j, a, b in ((0, 0, x, x), (1, 1, y, y), (2, 2, z, z), (0, 1, x, y), (0, 2, x, z),
                       (1, 2, y, z)):
        cov[:, i, j] = cov[:, j, i] = np.einsum("mk,mk->m", a, b) / k
    return cov


def _planes(reference: ReferenceMap, q: np.ndarray, cfg: PlaneRefinementConfig
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Plane fits around ``q`` (odometry frame): (valid mask, normals, centroids, normal
    variances) per point, and the rows of ``q`` that need more than one residual with their
    further normals (the first is in ``normals``): a point on a vertical line (``_lines``)
    once, with the line's second normal; a point in a blob (``_blobs``) up to twice, with the
    second and third of its weighted principal axes (``_blob_axes``) where the search did
    not cut the neighbourhood off along them (``max_blob_spread``).

    The variance of a fitted normal's tilt [rad^2] is about ``l3 / (k l2)`` (out-of-plane
    scatter over the in-plane spread of ``k`` points, ``l1 >= l2 >= l3`` the eigenvalues of the
    neighbourhood covariance)."""
    pts = reference.points
    k = min(cfg.normal_neighbors, len(pts))
    max_dist = cfg.max_neighbor_distance
    # neighbours beyond max_dist come back as inf (index len(pts)) and fail the check below
    dist, idx = reference.kdtree.query(q, k=k, distance_upper_bound=max_dist,
                                       workers=kdtree_workers(len(q)))
    if k == 1:
        dist, idx = dist[:, None], idx[:, None]
    valid = np.isfinite(dist[:, -1]) & (dist[:, -1] <= max_dist)
    normals = np.zeros((len(q), 3))
    centroids = np.zeros((len(q), 3))
    tilt_var = np.zeros(len(q))
    no_lines = np.zeros(0, dtype=int), np.zeros((0, 3))
    if not valid.any():
        return (valid, normals, centroids, tilt_var) + no_lines
    nb = pts[idx[valid]]  # (m, k, 3)
    c = np.einsum("mkj->mj", nb) / k  # the neighbourhoods' means (faster than mean(axis=1))
    cov = _covariances(nb - c[:, None, :])
    w, normal = symmetric_eigen3(cov)
    good = _planarity(w) >= cfg.min_planarity
    sel = np.flatnonzero(valid)
    valid[sel[~good]] = False
    normals[sel[good]] = normal[good]
    centroids[sel[good]] = c[good]
    tilt_var[sel[good]] = _tilt_variance(w[good], k)
    if not (cfg.vertical_lines or cfg.blobs):
        return (valid, normals, centroids, tilt_var) + no_lines
    rest, cov_rest, w_rest, c_rest = sel[~good], cov[~good], w[~good], c[~good]
    extra_rows, extra_normals = [no_lines[0]], [no_lines[1]]
    candidate = np.zeros(len(rest), dtype=bool)
    if cfg.vertical_lines:
        line, n1, n2 = _lines(cov_rest, w_rest, cfg)
        candidate[line] = True
        rows = rest[line]
        if cfg.line_neighbors > k and len(rows):
            wide = _wide_neighbourhoods(reference, q[rows], cfg)
            planar = rows[wide.planar]  # strips of a surface: its plane instead
            valid[planar] = True
            normals[planar] = wide.normals[wide.planar]
            centroids[planar] = wide.centroids[wide.planar]
            tilt_var[planar] = wide.tilt_var[wide.planar]
            line, n1, n2, rows = line[wide.line], n1[wide.line], n2[wide.line], rows[wide.line]
        valid[rows] = True
        normals[rows] = n1
        centroids[rows] = c_rest[line]
        wl = w_rest[line]
        tilt_var[rows] = np.maximum(wl[:, 1], 0.0) / (k * np.maximum(wl[:, 2], 1e-12))
        extra_rows.append(rows)
        extra_normals.append(n2)
    if cfg.blobs:
        blob = np.flatnonzero(~candidate & _blobs(w_rest, cfg))
        lam, axes = _blob_axes(cov_rest[blob], cfg.min_point_sigma)
        # an axis along which the neighbours spread as far as the search reached is cut off
        # by the search: its centroid follows the point and says nothing about the pose
        reach = dist[rest[blob], -1] ** 2  # dist rows are q's rows
        closed = lam <= cfg.max_blob_spread * reach[:, None]
        first = closed[:, 0]  # ascending: no axis is closed when the smallest is not
        rows, axes, closed, cb = rest[blob][first], axes[first], closed[first], c_rest[blob][first]
        valid[rows] = True
        normals[rows] = axes[:, 0]
        centroids[rows] = cb
        tilt_var[rows] = 0.0
        for i in (1, 2):
            extra_rows.append(rows[closed[:, i]])
            extra_normals.append(axes[closed[:, i], i])
    return (valid, normals, centroids, tilt_var, np.concatenate(extra_rows),
            np.vstack(extra_normals))


def _blobs(w: np.ndarray, cfg: PlaneRefinementConfig) -> np.ndarray:
    """Which neighbourhoods (ascending covariance eigenvalues ``w`` (m, 3)) are neither a
    plane (``min_planarity``) nor a line of any direction (``min_linearity``) and spread in
    every direction (smallest eigenvalue at least ``min_sphericity`` of the largest): a
    corner, the edge of a recess seen across, a lamp, a bracket."""
    top = np.maximum(w[:, 2], 1e-12)
    return ((_planarity(w) < cfg.min_planarity) & ((w[:, 2] - w[:, 1]) / top < cfg.min_linearity)
            & (w[:, 0] >= cfg.min_sphericity * top))


def _blob_axes(cov: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Ascending variances ``l`` (m, 3) [m^2] and weighted principal axes (m, 3, 3) of
    neighbourhoods with covariances ``cov`` (m, 3, 3): ``[:, i]`` is the unit eigenvector of
    ``l_i`` times ``sigma / sqrt(l_i + sigma^2)``, so the three point-to-plane residuals on
    these "normals" through the centroid make up the point-to-distribution distance of
    generalised ICP, in units of a plane residual of 1-sigma ``sigma`` [m]."""
    if not len(cov):
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    lam, vec = np.linalg.eigh(cov)
    scale = sigma / np.sqrt(np.maximum(lam, 0.0) + sigma**2)  # (m, 3)
    return lam, np.transpose(vec, (0, 2, 1)) * scale[:, :, None]


@dataclass
class WideNeighbourhoods:
    """What the wider neighbourhoods of points whose nearest neighbours form a vertical line
    are (:func:`_wide_neighbourhoods`), one row per point: ``line`` still a near-vertical
    line (a pole, a pipe), ``planar`` a plane (a strip of a wall), with that plane's unit
    ``normals``, ``centroids`` (odometry frame [m]) and normal tilt variances ``tilt_var``
    [rad^2] as :func:`_planes` gives a plane fit."""

    line: np.ndarray
    planar: np.ndarray
    normals: np.ndarray
    centroids: np.ndarray
    tilt_var: np.ndarray


def _wide_neighbourhoods(reference: ReferenceMap, q: np.ndarray, cfg: PlaneRefinementConfig
                         ) -> WideNeighbourhoods:
    """The ``line_neighbors`` nearest local-map points within ``max_neighbor_distance`` of
    each of the points ``q`` (odometry frame), at least ``normal_neighbors`` of them, as a
    near-vertical line (``min_linearity``, ``max_line_tilt_deg``) or a plane
    (``min_planarity``): a pole stays a line as its neighbourhood grows, a strip of points on a
    wall becomes the wall."""
    pts = reference.points
    k = min(cfg.line_neighbors, len(pts))
    dist, idx = reference.kdtree.query(q, k=k, distance_upper_bound=cfg.max_neighbor_distance)
    dist, idx = dist.reshape(len(q), k), idx.reshape(len(q), k)
    used = np.isfinite(dist)  # missing neighbours come back as inf, index len(pts)
    nb = pts[np.where(used, idx, 0)]  # (m, k, 3)
    count = used.sum(axis=1)
    weight = used / np.maximum(count, 1)[:, None]
    c = np.einsum("mk,mkj->mj", weight, nb)
    d = (nb - c[:, None, :]) * np.sqrt(weight)[..., None]
    cov = np.einsum("mki,mkj->mij", d, d)
    w, normal = symmetric_eigen3(cov)
    enough = count >= cfg.normal_neighbors
    line = np.zeros(len(q), dtype=bool)
    line[_lines(cov, w, cfg)[0]] = True
    planar = (_planarity(w) >= cfg.min_planarity) & enough
    return WideNeighbourhoods(line=line & enough & ~planar, planar=planar, normals=normal,
                              centroids=c, tilt_var=_tilt_variance(w, np.maximum(count, 1)))


def _planarity(w: np.ndarray) -> np.ndarray:
    """``(l2 - l3) / l1`` of neighbourhoods with ascending covariance eigenvalues ``w`` (m, 3)
    (``l1 >= l2 >= l3``; dimensionless, 1 for a plane, 0 for a line or a blob)."""
    return (w[:, 1] - w[:, 0]) / np.maximum(w[:, 2], 1e-12)


def _tilt_variance(w: np.ndarray, count) -> np.ndarray:
    """Variance [rad^2] of a fitted plane's normal tilt, ``l3 / (count l2)``: out-of-plane
    scatter over the in-plane spread of ``count`` points (ascending eigenvalues ``w``)."""
    return np.maximum(w[:, 0], 0.0) / (count * np.maximum(w[:, 1], 1e-12))


def _lines(cov: np.ndarray, w: np.ndarray, cfg: PlaneRefinementConfig
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which of the neighbourhoods (covariances ``cov`` (m, 3, 3), ascending eigenvalues ``w``)
    are near-vertical lines (``min_linearity``, ``max_line_tilt_deg``; odometry frame, z up),
    and two unit normals of each: horizontal-ish, orthogonal to each other and to the line.

    A thin pole, trunk or mast seen from a distance fills no plane, but its points hold a
    scan point across the pole: the point-to-line offset is the two point-to-plane residuals
    on planes through the line with those normals."""
    linearity = (w[:, 2] - w[:, 1]) / np.maximum(w[:, 2], 1e-12)
    cand = np.flatnonzero(linearity >= cfg.min_linearity)
    empty = np.zeros(0, dtype=int), np.zeros((0, 3)), np.zeros((0, 3))
    if not len(cand):
        return empty
    d = eigenvector3(cov[cand], w[cand, 2])
    vertical = np.abs(d[:, 2]) >= np.cos(np.deg2rad(cfg.max_line_tilt_deg))
    cand, d = cand[vertical], d[vertical]
    if not len(cand):
        return empty
    n1 = np.cross(d, np.eye(3)[np.argmin(np.abs(d), axis=1)])  # the axis farthest from d
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    return cand, n1, np.cross(d, n1)


@dataclass
class PlaneFits:
    """Local-map planes around a scan's points placed at one pose, for several refinements.

    Attributes:
        pose: 4x4 ``T_odom_lidar`` at which the points were associated.
        points: (N, 3) the scan points used (thinned to ``points``; a point on a vertical
            line once more at the end, for the line's second plane, a point in a blob up to
            twice more, for its second and third axes), LiDAR frame [m].
        valid: (N,) a plane was fitted for the point.
        normals, centroids: (N, 3) plane normals and centroids, odometry frame [m]; a blob's
            rows have weighted axes (``_blob_axes``, norm at most 1) as normals.
        tilt_var: (N,) variance of the fitted normal's tilt [rad^2].
    """

    pose: np.ndarray
    points: np.ndarray
    valid: np.ndarray
    normals: np.ndarray
    centroids: np.ndarray
    tilt_var: np.ndarray

    def near(self, pose: np.ndarray, max_translation: float = 0.05,
             max_rotation: float = 0.002) -> bool:
        """True when ``pose`` is within ``max_translation`` [m] and ``max_rotation`` [rad] of
        the pose the planes were found at, so they can serve a refinement starting there
        (a refinement keeps its associations while it moves anyway)."""
        d = np.linalg.inv(self.pose) @ np.asarray(pose, dtype=float)
        cos = np.clip(0.5 * (np.trace(d[:3, :3]) - 1.0), -1.0, 1.0)
        return (float(np.linalg.norm(d[:3, 3])) <= max_translation
                and float(np.arccos(cos)) <= max_rotation)


def fit_planes(points: np.ndarray, reference: ReferenceMap, pose: np.ndarray,
               config: PlaneRefinementConfig | None = None) -> PlaneFits:
    """Thin the scan to ``config.points``, place it at ``pose`` and fit a local-map plane to
    each point's ``normal_neighbors`` nearest map points (one k-d tree query); a point whose
    neighbours form a vertical line (``config.vertical_lines``) gets the line's two planes,
    the second as an extra row; a point in a blob (``config.blobs``) up to three rows, the
    second and third as extra rows."""
    cfg = config or PlaneRefinementConfig()
    pose = geometry.orthonormalize(np.asarray(pose, dtype=float))
    pts = geometry.drop_nonfinite_rows(np.asarray(points, dtype=float).reshape(-1, 3))
    pts = pts[:: max(1, -(-len(pts) // cfg.points))]
    if len(pts) < 10 or len(reference.points) < cfg.normal_neighbors:
        none = np.zeros((len(pts), 3))
        return PlaneFits(pose, pts, np.zeros(len(pts), bool), none, none.copy(),
                         np.zeros(len(pts)))
    q = pts @ pose[:3, :3].T + pose[:3, 3]
    valid, normals, centroids, tilt_var, line, n2 = _planes(reference, q, cfg)
    if len(line):  # further rows: a line's second plane, a blob's second and third axes
        pts = np.vstack([pts, pts[line]])
        valid = np.concatenate([valid, np.ones(len(line), bool)])
        normals = np.vstack([normals, n2])
        centroids = np.vstack([centroids, centroids[line]])
        tilt_var = np.concatenate([tilt_var, tilt_var[line]])
    return PlaneFits(pose, pts, valid, normals, centroids, tilt_var)


class PlaneFitCache:
    """One scan's plane fits (:func:`fit_planes`), found once and reused by the refinements
    of that scan that start near the same pose (:meth:`PlaneFits.near`); farther away they
    are found again. ``queries`` counts the k-d tree queries made."""

    def __init__(self, points: np.ndarray, reference: ReferenceMap,
                 config: PlaneRefinementConfig | None = None) -> None:
        self.points, self.reference = points, reference
        self.config = config or PlaneRefinementConfig()
        self.queries = 0
        self._fits: PlaneFits | None = None
        self._probe: tuple[np.ndarray, PlaneFits] | None = None

    def at(self, pose: np.ndarray) -> PlaneFits:
        """Plane fits usable for a refinement starting at ``pose``."""
        if self._fits is None and self._probe is not None:
            probed, fits = self._probe
            self._probe = None
            if np.array_equal(probed, pose):
                self._fits = fits
        if self._fits is None or not self._fits.near(pose):
            self._fits = fit_planes(self.points, self.reference, pose, self.config)
            self.queries += 1
        return self._fits

    def probe(self, pose: np.ndarray) -> PlaneFits:
        """Plane fits at ``pose`` for a check made before the refinements: the first later
        :meth:`at` reuses them only at exactly this pose and otherwise finds planes at its
        own, as if the probe had not been made."""
        if self._fits is not None or self._probe is not None:
            return self.at(pose)
        fits = fit_planes(self.points, self.reference, pose, self.config)
        self.queries += 1
        self._probe = (np.array(pose, dtype=float), fits)
        return fits


def _residuals(normals: np.ndarray, centroids: np.ndarray, points: np.ndarray,
               pose: np.ndarray) -> np.ndarray:
    """Signed point-to-plane residuals [m] of LiDAR-frame ``points`` placed at ``pose`` on the
    planes (``normals``, ``centroids``, odometry frame), one per row."""
    return np.einsum("ij,ij->i", normals, points @ pose[:3, :3].T + pose[:3, 3] - centroids)


def plane_cost(fits: PlaneFits, pose: np.ndarray,
               config: PlaneRefinementConfig | None = None) -> float:
    """Mean robust point-to-plane cost of the scan placed at ``pose`` on ``fits``
    (dimensionless, lower fits better): the Cauchy loss ``log(1 + (r / kernel)^2)`` of every
    fitted plane's residual, each residual capped at ``max_residual`` so a point that found
    no surface counts as a bad one rather than not at all. Two poses scored on the same fits
    are compared on the same points and planes."""
    cfg = config or PlaneRefinementConfig()
    if not np.any(fits.valid):
        return float("inf")
    v = fits.valid
    r = _residuals(fits.normals[v], fits.centroids[v], fits.points[v],
                   np.asarray(pose, dtype=float))
    r = np.minimum(np.abs(r), cfg.max_residual)
    return float(np.mean(np.log1p((r / cfg.kernel) ** 2)))


def _debiased(H: np.ndarray, points: np.ndarray, to_twist: np.ndarray,
              weights: np.ndarray) -> np.ndarray:
    """``H`` minus what the normals' fitting noise adds to it on average, PSD-clipped.

    A normal ``n + dn`` with an isotropic tilt of variance ``s^2`` adds
    ``s^2 A^T A`` to ``E[J^T J]`` (``J = n^T A``, ``A = [I, -[p]x] to_twist``): in a featureless
    tube the noise of the plane fits alone would otherwise claim centimetres along the axis.
    """
    Tv, Tw = to_twist[:3], to_twist[3:]
    # sum_m w_m A_m^T A_m with A_m = Tv - [p_m]x Tw, from the weighted moments of the points:
    # [p]x^T [p]x = |p|^2 I - p p^T, so only sum w, sum w p and sum w p p^T are needed
    sw = float(weights.sum())
    sp = weights @ points
    spp = (points * weights[:, None]).T @ points
    cross = Tv.T @ geometry.hat(sp) @ Tw
    noise = (sw * Tv.T @ Tv - cross - cross.T
             + Tw.T @ (np.trace(spp) * np.eye(3) - spp) @ Tw)
    out = 0.5 * ((H - noise) + (H - noise).T)
    w, v = np.linalg.eigh(out)
    return (v * np.clip(w, 0.0, None)) @ v.T


def refine_in_subspace(
    points: np.ndarray,
    reference: ReferenceMap,
    pose: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
    config: PlaneRefinementConfig | None = None,
    fits: PlaneFits | None = None,
) -> PlaneRefinement:
    """Point-to-plane Gauss-Newton of ``pose`` restricted to the subspace (module docstring).

    Args:
        points: (N, 3) scan points in the LiDAR frame [m] (deskewed).
        reference: the local map (odometry frame).
        pose: 4x4 start ``T_odom_lidar``.
        basis_scaled: (k, 6) subspace rows, scaled LiDAR body twists.
        length: characteristic length L [m] of the scaling.
        fits: planes already found for these points near ``pose`` (:func:`fit_planes`);
            None: found here. Correspondences are gated by their residual at ``pose``.
    """
    cfg = config or PlaneRefinementConfig()
    B = orthonormal_rows(basis_scaled)
    kdim = B.shape[0]
    pose = geometry.orthonormalize(np.asarray(pose, dtype=float))

    def empty(reason: str, used: int = 0) -> PlaneRefinement:
        return PlaneRefinement(pose, np.zeros((kdim, kdim)), np.zeros((6, 6)), B, used,
                               ok=False, details={"reason": reason})

    if kdim == 0:
        return PlaneRefinement(pose, np.zeros((0, 0)), np.zeros((6, 6)), B)
    if fits is None:
        fits = fit_planes(points, reference, pose, cfg)
    pts = fits.points
    if len(pts) < 10 or len(reference.points) < cfg.normal_neighbors:
        return empty("too few points")
    to_twist = np.linalg.inv(geometry.scaling_matrix(length)) @ B.T  # c -> plain body twist
    min_used = max(10, 2 * kdim)
    # one association at the start pose: the planes stay fixed while the pose moves inside
    # the subspace (steps are bounded by max_step, the planes are local surfaces)
    normals, centroids, tilt_var = fits.normals, fits.centroids, fits.tilt_var
    valid = fits.valid & (np.abs(_residuals(normals, centroids, pts, pose)) <= cfg.max_residual)
    used = int(valid.sum())
    if used < min_used:
        return empty("too few plane correspondences", used)
    p_used, n_used, c_used, var_used = pts[valid], normals[valid], centroids[valid], tilt_var[valid]
    for it in range(cfg.iterations + 1):
        R = pose[:3, :3]
        r = _residuals(n_used, c_used, p_used, pose)
        J = plane_jacobians(p_used, n_used @ R) @ to_twist  # (m, k)
        w = 1.0 / (1.0 + (r / cfg.kernel) ** 2)
        JW = J * w[:, None]
        H = JW.T @ J
        if it == cfg.iterations:
            break
        # damping: a prior of one point's weight keeps directions the planes do not see put
        step = -np.linalg.solve(H + np.eye(kdim), JW.T @ r)
        n = float(np.linalg.norm(step))
        if n > cfg.max_step:
            step *= cfg.max_step / n
        pose = geometry.orthonormalize(pose @ geometry.exp(to_twist @ step))
        if n < 1e-4:
            r = _residuals(n_used, c_used, p_used, pose)
            w = 1.0 / (1.0 + (r / cfg.kernel) ** 2)
            H = (J * w[:, None]).T @ J
            break
    if cfg.debias:
        H = _debiased(H, p_used, to_twist, w * var_used)
    sigma = max(cfg.min_point_sigma, 1.4826 * float(np.median(np.abs(r))))
    info = cfg.independent_fraction * H / sigma**2
    info = 0.5 * (info + info.T)
    return PlaneRefinement(pose, info, B.T @ info @ B, B, used, sigma,
                           details={"eigenvalues": np.linalg.eigvalsh(info).tolist()})


def returned_directions(points: np.ndarray, reference: ReferenceMap, refined: PlaneRefinement,
                        length: float, config: PlaneRefinementConfig | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Whether the scene holds each eigen-direction of ``refined``'s information: the
    refinement is run again from ``refined.pose`` moved by ``return_offset`` along the
    direction, on planes fitted again at the moved pose (the points re-associate), and the
    share of the offset still left at its result is the direction's return ratio.

    Returns ``(rows, ratios)``: the eigen-directions as rows (k, 6) of scaled LiDAR body
    twists (the characteristic length ``length`` [m]) and their return ratios (k,)
    (0: back at ``refined.pose``; 1 or more: stayed where it was put; inf: the moved
    refinement found too few planes). A direction with less than ``MIN_TESTED_INFORMATION``
    is not tested (ratio 0): it gives the fusion next to nothing either way.
    """
    cfg = config or PlaneRefinementConfig()
    info = 0.5 * (refined.information + refined.information.T)
    if not info.size:
        return np.zeros((0, 6)), np.zeros(0)
    w, V = np.linalg.eigh(info)
    rows = V.T @ refined.basis_scaled
    ratios = np.where(w < MIN_TESTED_INFORMATION, 0.0, np.inf)
    scale_inv = np.linalg.inv(geometry.scaling_matrix(length))
    base = geometry.orthonormalize(np.asarray(refined.pose, dtype=float))
    for i, row in enumerate(rows):
        if ratios[i] == 0.0:
            continue
        offset = cfg.return_offset * row
        start = geometry.orthonormalize(base @ geometry.exp(scale_inv @ offset))
        moved = refine_in_subspace(points, reference, start, refined.basis_scaled, length, cfg,
                                   fits=fit_planes(points, reference, start, cfg))
        if not moved.ok:
            continue
        left = geometry.scale_twist(geometry.log(np.linalg.inv(base) @ moved.pose), length)
        ratios[i] = float(left @ row) / cfg.return_offset
    return rows, ratios


def without_unheld(refined: PlaneRefinement, rows: np.ndarray, ratios: np.ndarray,
                   max_ratio: float, bounds: np.ndarray | None = None) -> PlaneRefinement:
    """``refined`` without the information along the directions ``rows`` (orthonormal rows
    of scaled twists inside its subspace) whose return ratio is above ``max_ratio``
    (:func:`returned_directions`); ``refined`` itself when every direction came back.

    ``bounds`` (one per row, [1/m^2]): instead of losing it, an unheld direction keeps its
    information up to its bound."""
    unheld = ~(np.abs(ratios) <= max_ratio)
    if not unheld.any():
        return refined
    U = rows[unheld] @ refined.basis_scaled.T  # (u, k) in the subspace coordinates
    P = np.eye(len(refined.information)) - U.T @ np.linalg.pinv(U @ U.T) @ U
    info = P @ refined.information @ P
    if bounds is not None:
        for u, bound in zip(U, np.asarray(bounds, dtype=float)[unheld]):
            u = u / np.linalg.norm(u)
            kept = min(float(u @ refined.information @ u), max(float(bound), 0.0))
            info = info + kept * np.outer(u, u)
    info = 0.5 * (info + info.T)
    B = refined.basis_scaled
    details = {**refined.details, "unheld": int(unheld.sum())}
    return replace(refined, information=info, information_scaled=B.T @ info @ B,
                   details=details)
