"""benchmarks/seeds.py: run names per configuration and method, and the table over seeds."""
from _benchmark_module import load_benchmark


def _load():
    return load_benchmark("seeds")


def test_run_names_and_table_per_method():
    seeds = _load()
    assert seeds._label("default") == "default"
    assert seeds._label("benchmarks/configs/frequent_detection.yaml") == "frequent_detection"
    assert seeds._label("default", "zhang") == "default_zhang"
    rows = [{"trial": 1, "seed": s, "config": label, "ate_m": ate, "rpe_m": 0.3}
            for s in (0, 1) for label, ate in (("default", 0.1 + s), ("default_zhang", 0.4))]
    lines = seeds._table(rows, [1], [0, 1], ["default", "default_zhang"])
    lili, zhang = lines[2:]
    assert lili.startswith("| 1 | `default` | 0.100 / 0.300 | 1.100 / 0.300 | 0.600 / 0.300 |")
    assert lili.endswith("1 of 2 |")  # seed 1's ATE misses the 0.25 m target
    assert zhang.startswith("| 1 | `default_zhang` |") and zhang.endswith("0 of 2 |")
