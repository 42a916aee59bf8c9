"""Configuration: the shipped YAML mirrors the dataclasses; bad parameters name themselves."""
from pathlib import Path

import numpy as np
import pytest

from lili_odom import geometry
from lili_odom.config import NodeConfig, apply_params, flatten, load_config, pose_from_xyz_rpy

ROOT = Path(__file__).resolve().parents[1]
YAML = ROOT / "config" / "lili_odom.yaml"
ADVANCED = ROOT / "config" / "lili_odom_advanced.yaml"


def _flat(d, prefix=""):
    out = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
    return out


def _params(path):
    import yaml

    return _flat(yaml.safe_load(path.read_text())["lili_odom"]["ros__parameters"])


def test_advanced_file_is_generated_from_the_dataclasses():
    from lili_odom.config import advanced_yaml

    assert ADVANCED.read_text() == advanced_yaml(), \
        "regenerate: python -m lili_odom.config advanced > config/lili_odom_advanced.yaml"


def test_robot_and_advanced_files_together_hold_every_parameter_once_with_its_default():
    from lili_odom.config import ROBOT_PARAMETERS

    robot, advanced = _params(YAML), _params(ADVANCED)
    assert set(robot) == set(ROBOT_PARAMETERS)
    assert not set(robot) & set(advanced)
    assert {**robot, **advanced} == flatten(NodeConfig())
    for path in (YAML, ADVANCED):
        cfg = load_config(path)
        assert cfg.pipeline.method == "lili"
        assert geometry.is_valid_pose(cfg.pipeline.fusion.T_base_lidar)


def test_every_advanced_parameter_is_documented():
    from lili_odom.config import ROBOT_PARAMETERS, parameter_docs

    docs = parameter_docs()
    assert set(docs) == set(flatten(NodeConfig()))
    assert [k for k, v in docs.items() if not v and k not in ROBOT_PARAMETERS] == []
    text = ADVANCED.read_text()
    assert "# scan points handed to the detector" in text


def test_all_defaults_file_round_trips():
    import yaml

    from lili_odom.config import default_yaml

    data = yaml.safe_load(default_yaml())["lili_odom"]["ros__parameters"]
    assert _flat(data) == flatten(NodeConfig())


def test_default_extrinsics_follow_the_ouster_convention():
    cfg = load_config(None)
    T_sensor_lidar = pose_from_xyz_rpy(cfg.extrinsics.sensor_to_lidar)
    # os_lidar is yawed 180 deg: its x axis points backwards in os_sensor
    assert np.allclose(T_sensor_lidar[:3, 0], [-1, 0, 0], atol=1e-12)
    assert T_sensor_lidar[2, 3] == pytest.approx(0.03618)
    assert np.allclose(cfg.pipeline.fusion.T_base_lidar, cfg.extrinsics.T_base_lidar())


@pytest.mark.parametrize("name, value, message", [
    ("pipeline.method", "magic", "method"),
    ("pipeline.lili.k", 1, "k"),
    ("pipeline.lili.k", 2.5, "pipeline.lili.k"),
    ("pipeline.scan_matcher.max_range", -5.0, "max_range"),
    ("publish_tf", "yes", "publish_tf"),
    ("no_such_parameter", 1, "no_such_parameter"),
    ("extrinsics.base_to_sensor", [0, 0, 1], "base_to_sensor"),
])
def test_invalid_parameters_are_rejected_with_their_name(name, value, message):
    with pytest.raises(ValueError, match=message):
        apply_params(NodeConfig(), {name: value})


def test_valid_override_applies():
    cfg = apply_params(NodeConfig(), {"pipeline.method": "none", "pipeline.lili.k": 4,
                                      "extrinsics.base_to_sensor": [0, 0, 1.0, 0, 0, 0]})
    assert cfg.pipeline.method == "none" and cfg.pipeline.lili.k == 4
    assert cfg.pipeline.fusion.T_base_lidar[2, 3] == pytest.approx(1.03618)


def test_apply_overrides_reads_yaml_scalars_below_the_prefix() -> None:
    from lili_odom.config import NodeConfig, apply_overrides

    cfg = apply_overrides(NodeConfig(), {"lili.return_ratio": "0.1", "fusion.use_imu": "false",
                                         "method": "zhang"})
    assert cfg.pipeline.lili.return_ratio == 0.1 and cfg.pipeline.fusion.use_imu is False
    assert cfg.pipeline.method == "zhang"
    with pytest.raises(ValueError, match="pipeline.lili.bogus"):
        apply_overrides(NodeConfig(), {"lili.bogus": "1"})
    with pytest.raises(ValueError, match="return_ratio"):
        apply_overrides(NodeConfig(), {"lili.return_ratio": "2.0"})


def test_an_unquoted_off_reads_as_the_off_value_of_a_string_parameter() -> None:
    from lili_odom.config import NodeConfig, apply_overrides

    cfg = apply_overrides(NodeConfig(), {"plane_refinement.return_check": "off",
                                         "plane_refinement.refine_constrained": "off"})
    cfg.validate()
    assert cfg.pipeline.plane_refinement.return_check == "off"
    assert cfg.pipeline.plane_refinement.refine_constrained == "off"
    with pytest.raises(ValueError, match="return_check"):  # "on" is not one of its values
        bad = apply_overrides(NodeConfig(), {"plane_refinement.return_check": "true"})
        bad.validate()


SHIPPED = sorted([ROOT / "config" / "deterministic.yaml",
                  *(ROOT / "benchmarks" / "configs").glob("*.yaml")])


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_parameter_files_load_validate_and_change_something(path):
    cfg = load_config(path)
    cfg.validate()
    assert flatten(cfg) != flatten(load_config(None)), f"{path.name} overrides nothing"


def test_deterministic_config_puts_every_native_thread_count_at_one():
    defaults = flatten(load_config(None))
    threads = [k for k in defaults if k.endswith("max_threads")]
    assert len(threads) >= 4  # the scan matcher and each detector's registration
    cfg = flatten(load_config(ROOT / "config" / "deterministic.yaml"))
    assert {k: cfg[k] for k in threads} == {k: 1 for k in threads}
