"""Where the node gets its pipeline from (pure Python, no rclpy).

The node asks a :class:`PipelineProvider` for the parameter names and defaults to declare, and
then for a pipeline built from the parameter values it ended up with. The default,
:class:`OdometryPipelineProvider`, serves :class:`lili_odom.pipeline.odometry.OdometryPipeline`
with its config dataclass (found through the ``config`` annotation of its constructor); tests
pass a provider of a fake pipeline instead.
"""
from __future__ import annotations

import inspect
import typing
from typing import Any, Mapping, Protocol

import numpy as np

from lili_odom.pipeline.types import ImuSample, OdometryOutput, Scan, WheelSample
from lili_odom.ros.params import build_config, flatten_config

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
    """Serves the real ``OdometryPipeline`` (imported lazily)."""

    def _classes(self) -> tuple[type, type]:
        from lili_odom.pipeline.odometry import OdometryPipeline

        hints = typing.get_type_hints(OdometryPipeline.__init__)
        config_cls = hints.get("config")
        if config_cls is None:
            params = list(inspect.signature(OdometryPipeline.__init__).parameters.values())
            raise RuntimeError("OdometryPipeline.__init__ has no annotated 'config' argument "
                               f"(parameters: {[p.name for p in params]})")
        args = typing.get_args(config_cls)  # Optional[Config] -> Config
        if args:
            config_cls = next(a for a in args if a is not type(None))
        return OdometryPipeline, config_cls

    def parameter_defaults(self) -> dict[str, Any]:
        _, config_cls = self._classes()
        return flatten_config(config_cls())

    def create(self, parameters: Mapping[str, Any]) -> PipelineLike:
        pipeline_cls, config_cls = self._classes()
        config = build_config(config_cls, parameters)
        validate = getattr(config, "validate", None)
        if callable(validate):
            validate()
        return pipeline_cls(config)
