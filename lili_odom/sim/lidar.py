"""Ouster OS1 model: ray casting a ``SceneMesh`` with Embree, one pose per column (motion skew).

Frames: rays start at the ``os_lidar`` origin of the pose of their own column; returned points
are expressed in ``os_lidar`` *at their column's time* (what the sensor reports: the cloud is
not de-skewed). Ring 0 is the top beam. Column j looks at azimuth ``2 pi (1 - j / cols)`` and is
measured ``j * period / cols`` seconds after the scan start.

Return model: true range + Gaussian noise, quantised to mm. A pixel returns when the range is
within [min_range, R_eff] with ``R_eff = max_range * sqrt(rho sqrt(cos(incidence)) / rho_ref)``
(inverse-square link budget: 120 m at 80 %, ~42 m at 10 % at normal incidence, matching the OS1
datasheet; ``sqrt(cos)`` is a rough-surface backscatter law), with a soft edge, plus a small
random dropout. Simplifications: beams all start at the lidar origin
(the OS1's 15.8 mm beam-origin offset and per-beam azimuth offsets are not modelled), no
multi-return, no blooming, no self-occlusion by the robot.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from lili_odom.sim.mesh import SceneMesh
from lili_odom.sim.sensors import LidarConfig

__all__ = ["RayCaster", "Scan", "LidarSimulator"]


class RayCaster:
    """Nearest-hit ray casting against a triangle mesh (Embree through ``embreex``)."""

    def __init__(self, mesh: SceneMesh):
        self.mesh = mesh
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, np.ascontiguousarray(mesh.triangles, dtype=np.float32))
        self.normals = mesh.face_normals.astype(np.float32)

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance to the first hit along unit ``directions`` (inf when none) and the hit
        triangle index (-1 when none). Inputs (N, 3) in the mesh frame."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        res = self._scene.run(o, d, output=1)
        prim = np.asarray(res["primID"]).astype(np.int64)
        dist = np.array(res["tfar"], dtype=np.float32)
        miss = prim < 0
        dist[miss] = np.inf
        prim[miss] = -1
        return dist, prim


@dataclass
class Scan:
    """One organised scan (rows x cols). ``stamp`` [s] is the scan start (trial time).

    ``xyz`` float32 (rows, cols, 3) in ``os_lidar`` (NaN for no return), ``range_mm`` uint32
    (0 for no return), ``intensity`` float32 (signal photons), ``reflectivity`` uint16,
    ``ambient`` uint16, ``t_ns`` uint32 (cols,) column time from ``stamp``."""

    stamp: float
    xyz: np.ndarray
    range_mm: np.ndarray
    intensity: np.ndarray
    reflectivity: np.ndarray
    ambient: np.ndarray
    t_ns: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return self.range_mm > 0


class LidarSimulator:
    """Simulate organised OS1 scans in a scene."""

    SIGNAL_GAIN = 2.0e5  # photons at 1 m from a 100 % target at normal incidence (arbitrary scale)
    AMBIENT_OUTDOOR = 600.0
    AMBIENT_INDOOR = 15.0
    AMBIENT_SKY = 900.0

    def __init__(self, config: LidarConfig, mesh: SceneMesh):
        self.cfg = config
        self.caster = RayCaster(mesh)
        el = config.elevations()
        az = config.azimuths()
        ce = np.cos(el)[:, None]
        self.directions = np.stack(
            [ce * np.cos(az)[None, :], ce * np.sin(az)[None, :], np.broadcast_to(np.sin(el)[:, None], (len(el), len(az)))],
            -1,
        )  # (rows, cols, 3) unit vectors in os_lidar
        self.directions32 = self.directions.astype(np.float32)
        self._miss_ambient = np.where(self.directions[..., 2] > 0, self.AMBIENT_SKY, self.AMBIENT_INDOOR).astype(np.float32)
        self.t_ns = np.round(config.column_times() * 1e9).astype(np.uint32)

    def column_times(self) -> np.ndarray:
        return self.cfg.column_times()

    def scan(self, T_world_lidar: np.ndarray, rng: np.random.Generator, stamp: float = 0.0) -> Scan:
        """Simulate one scan given the lidar pose of every column, (cols, 4, 4)."""
        cfg = self.cfg
        rows, cols = cfg.rows, cfg.cols
        R = T_world_lidar[:, :3, :3]
        o = T_world_lidar[:, :3, 3]
        d = self.directions32
        R = R.astype(np.float32)
        # world directions (rows, cols, 3): R_j @ d_ij, written as three broadcasts (fast)
        dw = d[..., 0:1] * R[None, :, :, 0] + d[..., 1:2] * R[None, :, :, 1] + d[..., 2:3] * R[None, :, :, 2]
        origins = np.broadcast_to(o[None], (rows, cols, 3))
        dist, prim = self.caster.cast(origins.reshape(-1, 3), dw.reshape(-1, 3))
        dist = dist.reshape(rows, cols)
        prim = prim.reshape(rows, cols)
        hit = prim >= 0
        mesh = self.caster.mesh
        pi = np.maximum(prim, 0)
        mat = mesh.material[pi]
        rho = np.where(hit, mesh.reflectivity.astype(np.float32)[mat], np.float32(0.0))
        cosi = np.abs((self.caster.normals[pi] * dw).sum(-1, dtype=np.float32))
        cosi = np.clip(cosi, 1e-3, 1.0)
        # rough-surface backscatter ~ rho * sqrt(cos): real concrete/gravel return more at grazing
        # incidence than a Lambertian model, so ground rings reach ~25 m as on a real OS1
        r_eff = cfg.max_range * np.sqrt(np.minimum(rho * np.sqrt(cosi) / cfg.max_range_reflectivity, 1.0))
        # one batch of random numbers per scan: uniform (detection) and 4 standard normals
        u = rng.random((rows, cols), dtype=np.float32)
        z = rng.standard_normal((4, rows, cols), dtype=np.float32)
        arg = np.clip((dist - r_eff) / np.maximum(0.04 * r_eff, 1e-3), -50.0, 50.0)
        p_detect = 1.0 / (1.0 + np.exp(arg))
        noisy = dist + cfg.range_sigma * z[0]
        ok = hit & (u < p_detect * (1.0 - cfg.dropout)) & (noisy >= cfg.min_range) & (noisy <= cfg.max_range)
        range_mm = np.round(np.where(ok, noisy, 0.0) / cfg.range_resolution_m).astype(np.uint32)
        r_q = range_mm.astype(np.float32) * np.float32(cfg.range_resolution_m)
        xyz = r_q[..., None] * self.directions32
        xyz[~ok] = np.nan
        # photometric channels
        sig = self.SIGNAL_GAIN * rho * np.sqrt(cosi) / np.maximum(r_q, 1.0) ** 2 * (1.0 + 0.05 * z[1])
        intensity = np.where(ok, np.clip(np.round(sig), 1, 65535), 0).astype(np.float32)
        refl = np.where(ok, np.clip(np.round(100.0 * rho * (1.0 + 0.03 * z[2])), 1, 255), 0)
        outdoor = hit & mesh.outdoor[mat]
        amb = np.where(hit, np.where(outdoor, self.AMBIENT_OUTDOOR, self.AMBIENT_INDOOR), self._miss_ambient)
        amb = np.clip(np.round(amb * (1.0 + 0.1 * z[3])), 0, 65535)
        return Scan(
            stamp=float(stamp),
            xyz=xyz,
            range_mm=range_mm,
            intensity=intensity,
            reflectivity=refl.astype(np.uint16),
            ambient=amb.astype(np.uint16),
            t_ns=self.t_ns.copy(),
        )
