"""Helpers for the ROS-side tests: a fake pipeline and an isolated DDS domain."""
from __future__ import annotations

import os
import random
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from lili_odom.pipeline.types import OdometryOutput


def isolated_ros_env() -> dict[str, str]:
    """Environment for a DDS test: a random domain id in 100..200, localhost discovery only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(random.randint(100, 200))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    return env


def wait_for(predicate: Callable[[], bool], timeout: float, step: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


@dataclass
class FakeConfig:
    voxel: float = 0.5
    method: str = "lili"


class FakePipeline:
    """Answers every scan with a pose moving 1 m along x and a 1-D degenerate basis."""

    def __init__(self, config: FakeConfig, delay: float = 0.0) -> None:
        self.config = config
        self.delay = delay
        self.scans: list[Any] = []
        self.imu: list[Any] = []
        self.wheel: list[Any] = []
        self.counters: dict[str, int] = {"scans": 0}

    def add_imu(self, sample: Any) -> None:
        self.imu.append(sample)

    def add_wheel(self, sample: Any) -> None:
        self.wheel.append(sample)

    def process_scan(self, scan: Any) -> OdometryOutput:
        if self.delay:
            time.sleep(self.delay)
        self.scans.append(scan)
        self.counters["scans"] += 1
        pose = np.eye(4)
        pose[0, 3] = float(len(self.scans))
        return OdometryOutput(stamp=scan.stamp, pose=pose, twist=np.zeros(6),
                              covariance=np.eye(6) * 0.01,
                              degenerate_basis=np.array([[1.0, 0, 0, 0, 0, 0]]))

    def local_map_points(self) -> np.ndarray:
        return np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])

    def reset(self) -> None:
        self.scans.clear()


@dataclass
class FakeProvider:
    delay: float = 0.0
    created: list[FakePipeline] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)

    def parameter_defaults(self) -> dict[str, Any]:
        return {"voxel": 0.5, "method": "lili"}

    def create(self, parameters: Mapping[str, Any]) -> FakePipeline:
        self.parameters = dict(parameters)
        p = FakePipeline(FakeConfig(float(parameters["voxel"]), str(parameters["method"])),
                         self.delay)
        self.created.append(p)
        return p
