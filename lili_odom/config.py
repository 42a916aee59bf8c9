"""The node/runner configuration: typed dataclasses mirrored by ``config/lili_odom.yaml``.

The YAML uses the ROS 2 parameter-file layout (``lili_odom: ros__parameters: {...}``); nested
mappings become dotted ROS parameter names (``pipeline.lili.k``), exactly as ``--params-file``
does on a real ROS install. ``load_config`` / ``config_from_params`` reject unknown names and
invalid values with a one-line message naming the parameter.
"""
from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lili_odom.errors import check_range
from lili_odom.pipeline.odometry import PipelineConfig

NODE_NAME = "lili_odom"


def pose_from_xyz_rpy(values: typing.Sequence[float]) -> np.ndarray:
    """4x4 from ``[x, y, z, roll, pitch, yaw]`` (m, rad; R = Rz(yaw) Ry(pitch) Rx(roll))."""
    x, y, z, roll, pitch, yaw = (float(v) for v in values)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    T = np.eye(4)
    T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    T[:3, 3] = [x, y, z]
    return T


@dataclass
class ExtrinsicsConfig:
    """Sensor mounting, ``[x, y, z, roll, pitch, yaw]`` in metres and radians.

    Used when the data carries no ``/tf_static`` (or ``use_tf_static`` is false).
    Defaults: an OS1 on a 0.40 m mast on the Husky top plate, 0.10 m ahead of base_link
    (robot specific: measure yours); ``os_lidar`` yawed 180 deg about z and 36.18 mm above
    ``os_sensor``; ``os_imu`` at (6.253, -11.775, 7.645) mm from ``os_sensor`` (Ouster
    datasheet / driver metadata).
    """

    base_to_sensor: list[float] = field(default_factory=lambda: [0.10, 0.0, 0.65, 0.0, 0.0, 0.0])
    sensor_to_lidar: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 0.03618, 0.0, 0.0, math.pi])
    sensor_to_imu: list[float] = field(
        default_factory=lambda: [0.006253, -0.011775, 0.007645, 0.0, 0.0, 0.0])
    use_tf_static: bool = True

    def T_base_lidar(self) -> np.ndarray:
        return pose_from_xyz_rpy(self.base_to_sensor) @ pose_from_xyz_rpy(self.sensor_to_lidar)

    def T_base_imu(self) -> np.ndarray:
        return pose_from_xyz_rpy(self.base_to_sensor) @ pose_from_xyz_rpy(self.sensor_to_imu)

    def validate(self) -> None:
        for name in ("base_to_sensor", "sensor_to_lidar", "sensor_to_imu"):
            v = getattr(self, name)
            if len(v) != 6 or not all(math.isfinite(float(x)) for x in v):
                raise ValueError(f"extrinsics.{name} must be 6 finite numbers [x y z roll pitch yaw]")


@dataclass
class NodeConfig:
    """Everything the node and the offline runner read.

    Attributes:
        lidar_topic / imu_topic / wheel_topic: inputs (design contract defaults).
        ground_truth_topic: truth in simulated bags (offline evaluation only).
        odom_frame: frame of the published odometry (default ``lili_odom`` so it never fights
            the robot's own EKF ``odom -> base_link``).
        base_frame: the robot body frame.
        publish_tf: publish ``odom_frame -> base_frame`` on ``/tf`` when tf2_msgs exists.
        map_publish_period_s: period of the latched ``~/map`` [s].
        path_max_poses: poses kept in ``~/path``.
        path_period: period of ``~/path`` [s of stamp time] (0: every scan).
        diagnostics_period: period of the node's diagnostics log line [s of wall time]
            (0: off).
        marker_arrow_length: length of the ``~/degeneracy`` arrows [m].
        scan_queue_size: scans allowed to wait while one is processed; when full, the oldest
            waiting scan is dropped (counted, logged). Each waiting scan holds its cloud
            message (about 6 MB for a full OS1-128 scan); a replay that must lose nothing
            however slow the machine queues the whole bag (up to 1000).
        scan_subscription_depth: history depth of the cloud subscription (sensor-data QoS),
            so clouds arriving while the executor is busy reach the node's queue.
        reliable_inputs: subscribe to the inputs RELIABLE instead of best effort (sensor-data
            QoS). Only for replays from a reliable publisher (``lili-odom play``, ``ros2 bag
            play`` of a reliable recording): a reliable subscription does not match the
            best-effort publishers of ouster-ros and most drivers.
        diagnostics_publish_period: period of ``/diagnostics`` [s of wall time] (0: off).
        lidar_rate_hz / imu_rate_hz / wheel_rate_hz: expected input rates [Hz] for
            ``/diagnostics`` and the missing-scan count (gaps between scan stamps longer
            than 1.5 LiDAR periods); 0: input not expected.
        map_save_path: file ``~/save_map`` writes (``.pcd`` or ``.ply``; relative to the
            node's working directory).
        map_save_voxel: voxel size of the saved map [m].
        map_save_max_points: points the saved map holds at most; beyond, its voxel size
            grows by half (bounded memory).
        map_accumulate_period_s: how often the local map is merged into the saved map [s of
            stamp time].
        publish_tf_inverse: publish ``base_frame -> odom_frame`` on ``/tf`` instead (for robots
            whose own EKF owns ``odom -> base_link``).
    """

    lidar_topic: str = "/ouster/points"
    imu_topic: str = "/ouster/imu"
    wheel_topic: str = "/platform/odom"
    ground_truth_topic: str = "/ground_truth/odom"
    odom_frame: str = "lili_odom"
    base_frame: str = "base_link"
    publish_tf: bool = True
    map_publish_period_s: float = 2.0
    path_max_poses: int = 20000
    path_period: float = 1.0
    diagnostics_period: float = 10.0
    marker_arrow_length: float = 2.0
    scan_queue_size: int = 3
    scan_subscription_depth: int = 10
    reliable_inputs: bool = False
    diagnostics_publish_period: float = 1.0
    lidar_rate_hz: float = 10.0
    imu_rate_hz: float = 100.0
    wheel_rate_hz: float = 50.0
    map_save_path: str = "lili_odom_map.pcd"
    map_save_voxel: float = 0.2
    map_save_max_points: int = 5000000
    map_accumulate_period_s: float = 1.0
    publish_tf_inverse: bool = False
    extrinsics: ExtrinsicsConfig = field(default_factory=ExtrinsicsConfig)
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)

    def validate(self) -> None:
        """Raise ``ValueError("<dotted.name> must be <range>, got <value>")`` for the first
        parameter out of its range (every nested configuration included)."""
        check_range("map_publish_period_s", self.map_publish_period_s, 0.0, 3600.0,
                    lo_open=True, unit="s")
        check_range("path_max_poses", self.path_max_poses, 1, 10**7)
        check_range("path_period", self.path_period, 0.0, 3600.0, unit="s")
        check_range("diagnostics_period", self.diagnostics_period, 0.0, 3600.0, unit="s")
        check_range("marker_arrow_length", self.marker_arrow_length, 0.0, 1000.0, lo_open=True,
                    unit="m")
        check_range("scan_queue_size", self.scan_queue_size, 1, 1000)
        check_range("scan_subscription_depth", self.scan_subscription_depth, 1, 1000)
        check_range("diagnostics_publish_period", self.diagnostics_publish_period, 0.0, 3600.0,
                    unit="s")
        for name in ("lidar_rate_hz", "imu_rate_hz", "wheel_rate_hz"):
            check_range(name, getattr(self, name), 0.0, 10000.0, unit="Hz")
        if not str(self.map_save_path).lower().endswith((".pcd", ".ply")):
            raise ValueError(f"map_save_path must end in .pcd or .ply, got {self.map_save_path!r}")
        check_range("map_save_voxel", self.map_save_voxel, 0.0, 100.0, lo_open=True, unit="m")
        check_range("map_save_max_points", self.map_save_max_points, 1, 10**9)
        check_range("map_accumulate_period_s", self.map_accumulate_period_s, 0.0, 3600.0,
                    unit="s")
        self.extrinsics.validate()
        _check_ranges(self)
        self.pipeline.fusion.validate("pipeline.fusion.")
        self.pipeline.detection_schedule.validate("pipeline.detection_schedule.")
        self.pipeline.validate()

    def apply_extrinsics(self) -> None:
        """Copy the configured extrinsics into the fusion configuration."""
        self.pipeline.fusion.T_base_lidar = self.extrinsics.T_base_lidar()
        self.pipeline.fusion.T_base_imu = self.extrinsics.T_base_imu()


# ---------------------------------------------------------------------------------------------
# parameter ranges of the configurations whose own validate() does not check them all
# (dotted name -> (low, high, low excluded, high excluded, unit); None = unbounded)

_INF = None
PARAMETER_RANGES: dict[str, tuple] = {
    "pipeline.sweep_duration": (0.0, 1.0, True, False, "s"),
    "pipeline.min_points": (10, 10**7, False, False, ""),
    "pipeline.max_backward_jump_s": (0.0, 3600.0, False, False, "s"),
    "pipeline.max_forward_gap_s": (0.0, 3600.0, True, False, "s"),
    "pipeline.detection_points": (0, 10**7, False, False, ""),
    "pipeline.sensor_wait_s": (0.0, 10.0, False, False, "s"),
    "pipeline.max_pending_scans": (1, 100, False, False, ""),
    "pipeline.remap_iterations": (0, 100, False, False, ""),
    "pipeline.scan_matcher.max_range": (0.0, 1000.0, True, False, "m"),
    "pipeline.scan_matcher.min_range": (0.0, 1000.0, False, True, "m"),
    "pipeline.scan_matcher.voxel_size": (0.0, 100.0, False, False, "m"),
    "pipeline.scan_matcher.max_points_per_voxel": (1, 10000, False, False, ""),
    "pipeline.scan_matcher.initial_threshold": (0.0, 100.0, True, False, "m"),
    "pipeline.scan_matcher.min_motion_th": (0.0, 10.0, False, False, "m"),
    "pipeline.scan_matcher.max_iterations": (1, 10000, False, False, ""),
    "pipeline.scan_matcher.convergence": (0.0, 1.0, True, False, ""),
    "pipeline.scan_matcher.max_threads": (0, 1024, False, False, ""),
    "pipeline.lili.k": (2, 100, False, False, ""),
    "pipeline.lili.tau_displacement": (0.0, 1.0, True, True, ""),
    "pipeline.lili.tau_pca": (0.0, _INF, True, False, ""),
    "pipeline.lili.ratio_points": (1, 10**7, False, False, ""),
    "pipeline.lili.min_points": (10, 10**7, False, False, ""),
    "pipeline.lili.return_ratio": (0.0, 1.0, False, True, ""),
    "pipeline.lili.return_check_iterations": (1, 10000, False, False, ""),
    "pipeline.zhang.eigenvalue_threshold": (0.0, _INF, True, False, ""),
    "pipeline.zhang.num_neighbors": (3, 100, False, False, ""),
    "pipeline.zhang.max_neighbor_distance": (0.0, 100.0, True, False, "m"),
    "pipeline.zhang.max_plane_deviation": (0.0, 100.0, True, False, "m"),
    "pipeline.zhang.min_weight": (0.0, 1.0, False, False, ""),
    "pipeline.zhang.min_correspondences": (6, 10**7, False, False, ""),
    "pipeline.hessian.threshold": (0.0, _INF, True, False, ""),
    "pipeline.hessian.normal_k": (3, 100, False, False, ""),
    "pipeline.hessian.min_planarity": (0.0, 1.0, False, False, ""),
    "pipeline.hessian.min_correspondences": (6, 10**7, False, False, ""),
}
for _det in ("lili", "zhang", "hessian"):
    PARAMETER_RANGES.update({
        f"pipeline.{_det}.registration.max_iterations": (1, 10000, False, False, ""),
        f"pipeline.{_det}.registration.convergence": (0.0, 1.0, True, False, ""),
        f"pipeline.{_det}.registration.max_correspondence_distance": (0.0, 100.0, False, False,
                                                                      "m"),
        f"pipeline.{_det}.registration.kernel": (0.0, 100.0, False, False, ""),
        f"pipeline.{_det}.registration.max_threads": (0, 1024, False, False, ""),
    })


def _check_ranges(config: "NodeConfig") -> None:
    from lili_odom.pipeline.odometry import METHODS

    if config.pipeline.method not in METHODS:
        raise ValueError(f"pipeline.method must be one of {', '.join(METHODS)}, "
                         f"got {config.pipeline.method!r}")
    values = flatten(config)
    for name, (lo, hi, lo_open, hi_open, unit) in PARAMETER_RANGES.items():
        if name in values:
            check_range(name, values[name], lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
    sm = config.pipeline.scan_matcher
    if not sm.min_range < sm.max_range:
        raise ValueError(f"pipeline.scan_matcher.min_range must be < pipeline.scan_matcher."
                         f"max_range ({sm.max_range:g} m), got {sm.min_range!r}")


# ---------------------------------------------------------------------------------------------
# flat dotted parameters <-> nested dataclasses

def _is_dataclass_field(f: dataclasses.Field, hints: dict[str, Any]) -> bool:
    return dataclasses.is_dataclass(hints.get(f.name))


def flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """Dotted-name parameters of a config tree (numpy-array fields are derived, left out)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            out.update(flatten(value, name + "."))
        elif isinstance(value, np.ndarray):
            continue
        elif isinstance(value, (list, tuple)):
            out[name] = [float(v) for v in value]
        else:
            out[name] = value
    return out


def _coerce(name: str, value: Any, current: Any) -> Any:
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise ValueError(f"parameter '{name}' must be true or false, got {value!r}")
        return value
    if isinstance(current, int) and not isinstance(current, bool):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value:
            raise ValueError(f"parameter '{name}' must be an integer, got {value!r}")
        return int(value)
    if isinstance(current, float) or (current is None and isinstance(value, (int, float))):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"parameter '{name}' must be a finite number, got {value!r}")
        return float(value)
    if isinstance(current, str):
        if not isinstance(value, str):
            raise ValueError(f"parameter '{name}' must be a string, got {value!r}")
        return value
    if isinstance(current, list):
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"parameter '{name}' must be a list, got {value!r}")
        return [float(v) for v in value]
    return value


def apply_params(config: NodeConfig, params: dict[str, Any]) -> NodeConfig:
    """Set dotted parameters on ``config``; unknown names or bad values raise ValueError."""
    known = flatten(config)
    for name, value in params.items():
        if name in ("use_sim_time",):
            continue
        if name not in known:
            raise ValueError(f"unknown parameter '{name}'")
        *path, leaf = name.split(".")
        target = config
        for part in path:
            target = getattr(target, part)
        setattr(target, leaf, _coerce(name, value, getattr(target, leaf)))
    config.validate()
    config.apply_extrinsics()
    return config


def apply_overrides(config: NodeConfig, overrides: dict[str, Any],
                    prefix: str = "pipeline.") -> NodeConfig:
    """``apply_params`` for command-line style overrides: names below ``prefix`` (e.g.
    ``lili.return_ratio``), string values read as YAML scalars (``"0.1"``, ``"false"``)."""
    import yaml

    return apply_params(config, {prefix + k.strip(): yaml.safe_load(v) if isinstance(v, str) else v
                                 for k, v in overrides.items()})


def _flatten_mapping(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten_mapping(value, name + "."))
        else:
            out[name] = value
    return out


def load_config(path: str | Path | None = None, node_name: str = NODE_NAME) -> NodeConfig:
    """Defaults, overridden by a ROS 2 parameter file (``node: ros__parameters: ...``)."""
    config = NodeConfig()
    if path is None:
        config.validate()
        config.apply_extrinsics()
        return config
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text()) or {}
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise ValueError(f"{path}: not a valid YAML file{line}: {problem}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a ROS 2 parameter file ('{node_name}: "
                         f"ros__parameters: ...'), got a {type(data).__name__}")
    section = data.get(node_name, data.get(f"/{node_name}", data.get("/**", {})))
    if section is not None and not isinstance(section, dict):
        raise ValueError(f"{path}: '{node_name}' must be a mapping")
    params = (section or {}).get("ros__parameters", {})
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise ValueError(f"{path}: '{node_name}.ros__parameters' must be a mapping")
    return apply_params(config, _flatten_mapping(params))


def default_config_path() -> Path | None:
    """``config/lili_odom.yaml`` of the source tree or of the installed ament share dir."""
    here = Path(__file__).resolve().parents[1] / "config" / "lili_odom.yaml"
    if here.is_file():
        return here
    try:
        from ament_index_python.packages import get_package_share_directory

        p = Path(get_package_share_directory("lili_odom")) / "config" / "lili_odom.yaml"
        return p if p.is_file() else None
    except Exception:  # noqa: BLE001 - no ament index outside ROS
        return None




YAML_HEADER = """\
# lili_odom parameters (ROS 2 parameter-file layout).
#   ros2 run lili_odom lili_odom_node --ros-args --params-file config/lili_odom.yaml
#   lili-odom run BAG --config config/lili_odom.yaml
# Every value below is the built-in default (lili_odom/config.py and the dataclasses it nests);
# regenerate with `python -m lili_odom.config > config/lili_odom.yaml`. Units are SI (m, s,
# rad). Extrinsics are [x, y, z, roll, pitch, yaw]; the bag's or robot's /tf_static replaces
# them when extrinsics.use_tf_static is true and it is available.
"""


def default_yaml() -> str:
    """The parameter file holding every default, nested as ROS expects."""
    import yaml

    class _Dumper(yaml.SafeDumper):
        pass

    _Dumper.add_representer(
        list, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v, flow_style=True))
    nested: dict[str, Any] = {}
    for name, value in flatten(NodeConfig()).items():
        node = nested
        *path, leaf = name.split(".")
        for part in path:
            node = node.setdefault(part, {})
        node[leaf] = value
    body = yaml.dump({NODE_NAME: {"ros__parameters": nested}}, Dumper=_Dumper, sort_keys=False,
                     default_flow_style=False, width=100)
    return YAML_HEADER + body


if __name__ == "__main__":
    print(default_yaml(), end="")
