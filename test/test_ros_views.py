"""The shipped views (RViz2, Foxglove), DDS profile and launch options: installed and
pointing at the node's topics. (No rviz2, Foxglove or launch here: the files are checked
for what those tools read.)"""
from __future__ import annotations

import ast
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
TOPICS = {"/lili_odom/odometry", "/lili_odom/path", "/lili_odom/map", "/lili_odom/degeneracy",
          "/ouster/points"}


def _data_files() -> str:
    src = (ROOT / "setup.py").read_text()
    call = next(n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.Call)
                and getattr(n.func, "id", "") == "setup")
    value = next(k.value for k in call.keywords if k.arg == "data_files")
    return ast.get_source_segment(src, value)


def test_views_and_profile_are_installed():
    src = _data_files()
    for folder, pattern in (("config/dds", "config/dds/*.xml"), ("rviz", "rviz/*.rviz"),
                            ("foxglove", "foxglove/*.json")):
        assert f'"/{folder}", glob("{pattern}")' in src, folder
        assert list(ROOT.glob(pattern)), pattern


def _topics(node) -> set[str]:
    found = set()
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "Topic" and isinstance(v, dict):
                found.add(v.get("Value"))
            found |= _topics(v)
    elif isinstance(node, list):
        for v in node:
            found |= _topics(v)
    return found


def test_rviz_config_shows_every_output_in_the_odometry_frame():
    cfg = yaml.safe_load((ROOT / "rviz" / "lili_odom.rviz").read_text())
    manager = cfg["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "lili_odom"
    assert TOPICS <= _topics(manager["Displays"])
    classes = {d["Class"] for d in manager["Displays"]}
    assert {"rviz_default_plugins/Odometry", "rviz_default_plugins/Path",
            "rviz_default_plugins/PointCloud2", "rviz_default_plugins/MarkerArray"} <= classes
    latched = next(d for d in manager["Displays"] if d.get("Name") == "Map")
    assert latched["Topic"]["Durability Policy"] == "Transient Local"  # ~/map is latched
    scan = next(d for d in manager["Displays"] if d.get("Name") == "Scan")
    assert scan["Topic"]["Reliability Policy"] == "Best Effort"  # matches any driver


def test_foxglove_layout_has_the_3d_view_and_the_diagnostics():
    layout = json.loads((ROOT / "foxglove" / "lili_odom_layout.json").read_text())
    panels = layout["configById"]
    three_d = next(v for k, v in panels.items() if k.startswith("3D!"))
    assert TOPICS <= set(three_d["topics"])
    assert any(k.startswith("DiagnosticSummary!") and v["topicToRender"] == "/diagnostics"
               for k, v in panels.items())

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert set(leaves(layout["layout"])) == set(panels)  # every panel is placed


def test_launch_file_compiles_and_offers_rviz_and_the_dds_profile():
    src = (ROOT / "launch" / "lili_odom.launch.py").read_text()
    compile(src, "lili_odom.launch.py", "exec")
    tree = ast.parse(src)
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    args = {ast.literal_eval(c.args[0]) for c in calls
            if getattr(c.func, "id", "") == "DeclareLaunchArgument"}
    assert {"rviz", "rviz_config", "dds_profile", "params_file", "use_sim_time"} <= args
    rviz = next(c for c in calls if getattr(c.func, "id", "") == "Node"
                and any(k.arg == "package" and ast.literal_eval(k.value) == "rviz2"
                        for k in c.keywords))
    cond = next(k.value for k in rviz.keywords if k.arg == "condition")
    assert cond.func.id == "IfCondition" and "rviz" in ast.dump(cond)
    env = next(c for c in calls if getattr(c.func, "id", "") == "SetEnvironmentVariable")
    assert ast.literal_eval(env.args[0]) == "FASTRTPS_DEFAULT_PROFILES_FILE"
    assert '"dds", "fastdds.xml"' in src and '"rviz", "lili_odom.rviz"' in src


def test_dds_profile_is_valid_fast_dds_xml_with_a_large_shared_memory_segment():
    root = ET.parse(ROOT / "config" / "dds" / "fastdds.xml").getroot()
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    shm = [t for t in root.findall("f:transport_descriptors/f:transport_descriptor", ns)
           if t.findtext("f:type", namespaces=ns) == "SHM"]
    assert shm and int(shm[0].findtext("f:segment_size", namespaces=ns)) >= 16 * 2**20
    participant = root.find("f:participant", ns)
    assert participant.get("is_default_profile") == "true"
    used = {e.text for e in participant.findall("f:rtps/f:userTransports/f:transport_id", ns)}
    ids = {t.findtext("f:transport_id", namespaces=ns)
           for t in root.findall("f:transport_descriptors/f:transport_descriptor", ns)}
    assert used == ids and len(ids) == 2  # shared memory and UDPv4, as Fast DDS's default
    assert participant.findtext("f:rtps/f:useBuiltinTransports", namespaces=ns) == "false"
