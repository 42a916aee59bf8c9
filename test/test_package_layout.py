"""The ament_python package: what colcon installs and what ros2 run / ros2 launch find.

There is no colcon, ros2cli or launch here, so the files are checked for the facts those tools
rely on: the ament index marker, package.xml, the executable name in lib/<package> and the
launch file's references.
"""
from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setup_call() -> ast.Call:
    tree = ast.parse((ROOT / "setup.py").read_text())
    return next(n for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, "id", "") == "setup")


def _keyword(call: ast.Call, name: str):
    return next(k.value for k in call.keywords if k.arg == name)


def test_package_xml_is_an_ament_python_package_named_like_the_marker():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == "lili_odom"
    assert root.find("export/build_type").text == "ament_python"
    assert (ROOT / "resource" / "lili_odom").is_file()
    deps = {e.text for e in root.findall("exec_depend")}
    assert {"rclpy", "sensor_msgs", "nav_msgs", "launch_ros"} <= deps


def test_node_executable_lands_in_lib_package_for_ros2_run():
    cfg = (ROOT / "setup.cfg").read_text()
    assert "install_scripts=$base/lib/lili_odom" in cfg
    scripts = ast.literal_eval(_keyword(_setup_call(), "entry_points"))["console_scripts"]
    names = {s.split("=")[0].strip(): s.split("=")[1].strip() for s in scripts}
    assert names["lili_odom_node"] == "lili_odom.ros.node:main"


def test_data_files_install_marker_manifest_config_and_launch():
    src = ast.get_source_segment((ROOT / "setup.py").read_text(),
                                 _keyword(_setup_call(), "data_files"))
    for needle in ("resource_index/packages", "package.xml", "config/*.yaml",
                   "launch/*.launch.py"):
        assert needle in src, needle
    assert list((ROOT / "launch").glob("*.launch.py"))


def test_launch_file_starts_the_installed_executable_with_the_node_name_and_params():
    src = (ROOT / "launch" / "lili_odom.launch.py").read_text()
    tree = ast.parse(src)  # valid Python
    node = next(n for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, "id", "") == "Node")
    kw = {k.arg: k.value for k in node.keywords}
    assert ast.literal_eval(kw["package"]) == "lili_odom"
    assert ast.literal_eval(kw["executable"]) == "lili_odom_node"
    assert ast.literal_eval(kw["name"]) == "lili_odom"  # so outputs are /lili_odom/...
    assert '"lili_odom.yaml"' in src and '"lili_odom_advanced.yaml"' in src
    assert "use_sim_time" in src
    assert (ROOT / "config" / "lili_odom.yaml").is_file()
    assert (ROOT / "config" / "lili_odom_advanced.yaml").is_file()
