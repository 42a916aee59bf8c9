"""``lili-odom evaluate``: a tiny tunnel evaluation writes the table, JSON and figure."""
from __future__ import annotations

import json

from lili_odom.cli import main


def test_evaluate_writes_table_json_and_figure(tmp_path, capsys):
    out = tmp_path / "eval"
    code = main(["evaluate", "--trials", "3", "--methods", "none", "zhang", "--resolution",
                 "16x128", "--duration", "3", "--out", str(out), "--cache-dir",
                 str(tmp_path / "cache"), "--no-progress"])
    assert code == 0
    report = json.loads((out / "tunnel.json").read_text())
    rows = {(r["trial"], r["method"]): r for r in report["rows"]}
    assert set(rows) == {(3, "none"), (3, "zhang")}
    for r in rows.values():
        assert r["scans_processed"] == r["scans_in_bag"] == 30
        assert r["verdict"] in ("ok", "failed")
        assert 0.0 <= r["ate_rmse_m"] < 5.0 and r["path_length_m"] > 0.0
    assert rows[(3, "none")]["degenerate_fraction"] == 0.0
    table = (out / "tunnel.md").read_text()
    assert "| 3 | zhang |" in table and "lili-odom evaluate --trials 3" in table
    assert (out / "tunnel_trial3.png").stat().st_size > 10_000
    # a second call with --reuse takes the finished runs instead of running again
    code = main(["evaluate", "--trials", "3", "--methods", "none", "--resolution", "16x128",
                 "--duration", "3", "--out", str(out), "--cache-dir", str(tmp_path / "cache"),
                 "--no-progress", "--reuse"])
    assert code == 0 and "reusing" in capsys.readouterr().out


def test_evaluate_rejects_bad_options(tmp_path, capsys):
    assert main(["evaluate", "--jobs", "0", "--out", str(tmp_path)]) != 0
    assert "--jobs" in capsys.readouterr().err
