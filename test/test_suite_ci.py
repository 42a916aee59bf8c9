"""The scenario suite's ``ci`` preset end to end: simulated bags (cached), our ``none`` and
``lili`` and the wheel odometry on every scenario with a CI piece, scored alike; per scenario
``lili`` must beat ``none`` and ``wheels`` in ATE. The peers (KISS-ICP, GenZ-ICP, RKO-LIO)
run on one CI piece when their packages are installed."""
from __future__ import annotations

import json
import math

import pytest

from lili_odom.suite.jobs import ROW_KEYS
from lili_odom.suite.methods import peer_available
from lili_odom.suite.runner import SuiteRequest, run_suite, select_scenarios


def _ci_scenarios() -> list[str]:
    try:
        return [s.name for s in select_scenarios(SuiteRequest(out=".", preset="ci"))]
    except (ValueError, OSError):
        return []


CI = _ci_scenarios()
pytestmark = pytest.mark.skipif(not CI, reason="no scenario with a CI piece")


def _run(tmp_path, methods, scenarios=None):
    from lili_odom.suite.backends import LocalBackend

    out = tmp_path / "suite"
    request = SuiteRequest(out=out, preset="ci", methods=methods, scenarios=scenarios,
                           command="lili-odom suite --preset ci")
    doc = run_suite(request, LocalBackend(jobs=2), progress=False)
    assert json.loads((out / "suite.json").read_text()) == doc
    return out, doc


def test_ci_preset_lili_beats_none_and_wheels(tmp_path):
    out, doc = _run(tmp_path, ["none", "lili", "wheels"])
    assert doc["backend"] == "local"
    rows = {(r["scenario"], r["method"]): r for r in doc["rows"]}
    assert len(rows) == 3 * len(CI) == len(doc["rows"])
    for r in doc["rows"]:
        assert set(ROW_KEYS) <= set(r)
        assert "error" not in r, f"{r['scenario']} {r['method']}: {r.get('error')}"
        assert r["split"] in ("tuning", "validation")
        assert math.isfinite(r["ate_m"]) and r["distance_m"] > 5.0
    for name in CI:
        lili, none, wheels = (rows[(name, m)] for m in ("lili", "none", "wheels"))
        assert lili["ate_m"] < none["ate_m"], f"{name}: lili {lili['ate_m']:.3f} m, none {none['ate_m']:.3f} m"
        assert lili["ate_m"] < wheels["ate_m"], f"{name}: lili {lili['ate_m']:.3f} m, wheels {wheels['ate_m']:.3f} m"
        assert 0.0 <= lili["degenerate_fraction"] <= 1.0 and lili["scans_per_s"] > 0
        assert wheels["degenerate_fraction"] is None
        assert (out / f"{name}.png").stat().st_size > 10_000
    # the jobs ran the odometry as `lili-odom run` does: detections in the background (where
    # LiLi is asked at all: the planes give the subspace where they hold every direction)
    background = [json.loads(next((out / "runs" / name).glob("seed*/lili/metrics.json"))
                             .read_text())["counters"].get("detections_background", 0)
                  for name in CI]
    assert max(background) > 0, background
    md = (out / "suite.md").read_text()
    assert "lili-odom suite --preset ci" in md
    for name in CI:
        assert f"### {name}" in md


@pytest.mark.skipif(not all(peer_available(p) for p in ("kiss", "genz", "rko")),
                    reason="peers not installed (pip install 'lili_odom[peers]')")
def test_ci_peers_run_in_the_same_frame(tmp_path):
    """The peers on the first CI piece: every scan registered, finite scores, and their
    trajectories (converted to base_link) end near the truth's path length."""
    out, doc = _run(tmp_path, ["kiss", "genz", "rko", "wheels"], scenarios=CI[:1])
    rows = {r["method"]: r for r in doc["rows"]}
    assert set(rows) == {"kiss", "genz", "rko", "wheels"}
    for m, r in rows.items():
        assert "error" not in r, f"{m}: {r.get('error')}"
        assert math.isfinite(r["ate_m"]) and math.isfinite(r["final_m"])
    scans = {m: rows[m]["scans"] for m in ("kiss", "genz", "rko")}
    assert min(scans.values()) > 0.9 * max(scans.values()), scans
    # the converted peer trajectory is base_link's: it starts where the truth starts (the
    # anchored end-point error would otherwise include the lever arm of the mounting)
    from lili_odom.bagio.tum import read_tum

    for m in ("kiss", "genz"):
        _, poses = read_tum(out / "runs" / CI[0] / "seed{}".format(rows[m]["seed"]) / m / "estimate_base.tum")
        assert abs(poses[0, :3, 3]).max() < 1e-6


def test_users_bags_are_rows_of_split_user(tmp_path):
    """``--bags``: a recorded bag with a truth topic is run like a scenario (here the wheel
    odometry on the first CI piece's bag)."""
    from lili_odom.suite.backends import LocalBackend
    from lili_odom.suite.scenario import load_scenarios, scenario_bag

    (sc,) = load_scenarios([CI[0]])
    bag = scenario_bag(sc, sc.seeds[0], ci=True, progress=False)
    request = SuiteRequest(out=tmp_path / "user", bags=[bag], methods=["wheels"])
    doc = run_suite(request, LocalBackend(jobs=1), progress=False)
    (row,) = doc["rows"]
    assert row["split"] == "user" and row["scenario"] == bag.name
    assert "error" not in row and math.isfinite(row["ate_m"]) and row["distance_m"] > 5.0
    assert "## User scenarios" in (tmp_path / "user" / "suite.md").read_text()
