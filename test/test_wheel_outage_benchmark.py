"""benchmarks/wheel_outage.py: the paired comparison and the reuse of stored runs."""
import argparse
import json

import pytest

from _benchmark_module import load_benchmark


def _load():
    return load_benchmark("wheel_outage")


def _row(config, seed, start, final, repeat=0):
    return {"config": config, "seed": seed, "start": start, "repeat": repeat, "final_m": final,
            "ate_m": final / 2}


def test_paired_differences_against_the_first_configuration():
    wo = _load()
    rows = [_row("default", 0, 70.0, 2.0), _row("default", 0, 70.0, 4.0, repeat=1),
            _row("default", 1, 70.0, 1.0), _row("default", 2, 70.0, 5.0),
            _row("other", 0, 70.0, 1.0), _row("other", 1, 70.0, 2.0),
            _row("other", 2, 70.0, 1.0)]
    lines = wo._paired(rows, ["default", "config/other.yaml"])
    (line,) = lines[2:]
    # windows: (3 - 1), (1 - 2), (5 - 1) -> mean +1.67, default further off in 2 of 3
    assert line.startswith("| `other` | 3 | +1.67 | 2 of 3 |")
    assert 0.0 < float(line.split("|")[5]) <= 1.0


def test_reuse_takes_only_runs_of_the_same_arguments(tmp_path):
    wo = _load()
    stored = {"trial": 1, "resolution": "32x256", "duration_s": 40.0, "outage_s": 20.0,
              "threads": 1, "runs": [_row("default", 0, 70.0, 1.0), _row("default", 1, 70.0, 2.0)]}
    (tmp_path / "wheel_outage.json").write_text(json.dumps(stored))
    args = argparse.Namespace(out=tmp_path, seeds=[0, 1], starts=[70.0], configs=["default"],
                              repeats=1, trial=1, resolution="32x256", duration=40.0,
                              outage=20.0, threads=1)
    assert len(wo._reused_rows(args)) == 2
    for change in ({"seeds": [0, 1, 2]}, {"threads": 0}, {"repeats": 2}):
        with pytest.raises(SystemExit, match="other runs"):
            wo._reused_rows(argparse.Namespace(**{**vars(args), **change}))
