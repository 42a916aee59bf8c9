"""Where the node gets its pipeline from (pure Python, no rclpy).

The node asks a :class:`PipelineProvider` for the parameter names and defaults to declare, and
then for a pipeline built from the parameter values it ended up with. The default,
:class:`OdometryPipelineProvider`, serves :class:`lili_odom.pipeline.odometry.OdometryPipeline`
configured by :class:`lili_odom.config.NodeConfig`; tests pass a provider of a fake pipeline.
"""
from __future__ import annotations

from typing import Any, Mapping, Protocol

import numpy as np

from lili_odom.pipeline.types import ImuSample, OdometryOutput, Scan, WheelSample

__all__ = ["PipelineLike", "PipelineProvider", "OdometryPipelineProvider"]


class PipelineLike(Protocol):
    """The part of ``OdometryPipeline`` the node uses."""

    counters: dict[str, int]

    def add_imu(self, sample: ImuSample) -> None: ...

    def add_wheel(self, sample: WheelSample) -> None: ...

    def process_scan(self, scan: Scan) -> OdometryOutput | None: ...

    def local_map_points(self) -> np.ndarray: ...

    def reset(self) -> None: ...


class PipelineProvider(Protocol):
    def parameter_defaults(self) -> dict[str, Any]:
        """``{dotted parameter name: default}`` to declare on the node."""

    def create(self, parameters: Mapping[str, Any]) -> PipelineLike:
        """A pipeline configured from the node's parameter values."""


class OdometryPipelineProvider:
    """Serves the real ``OdometryPipeline`` configured through ``lili_odom.config.NodeConfig``.

    The parameters are NodeConfig's dotted names (``lidar_topic``, ``extrinsics.*``,
    ``pipeline.lili.k`` ...): the robot settings of ``config/lili_odom.yaml`` together with the
    tuning of ``config/lili_odom_advanced.yaml``. ``create`` applies only the
    names NodeConfig knows (node-only extras such as ``path_period`` are ignored here) and
    raises ``ValueError`` naming a bad parameter.
    """

    def parameter_defaults(self) -> dict[str, Any]:
        from lili_odom.config import NodeConfig, flatten

        return flatten(NodeConfig())

    def node_config(self, parameters: Mapping[str, Any]) -> Any:
        from lili_odom.config import NodeConfig, apply_params, flatten

        known = flatten(NodeConfig())
        values = {k: v for k, v in parameters.items() if k in known and v is not None}
        return apply_params(NodeConfig(), values)

    def create(self, parameters: Mapping[str, Any]) -> PipelineLike:
        from lili_odom.pipeline.odometry import OdometryPipeline

        config = self.node_config(parameters)
        wait = config.detection_max_wait_s
        return OdometryPipeline(config.pipeline, max_detection_wait_s=wait if wait > 0 else None)
