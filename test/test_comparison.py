"""benchmarks._comparison: run names, the table over seeds, paired differences and
the reuse of stored runs (the benchmarks' seeds and wheel-outage reports)."""
from benchmarks._comparison import matching_runs, paired_table, run_label, seeds_table

TARGETS = {1: {"ate_m": 0.25, "rpe_m": 0.40}, 2: {"ate_m": 0.45}}


def test_run_names_and_table_per_method():
    assert run_label("default") == "default"
    assert run_label("benchmarks/configs/frequent_detection.yaml") == "frequent_detection"
    assert run_label("default", "zhang") == "default_zhang"
    rows = [{"trial": 1, "seed": s, "config": label, "ate_m": ate, "rpe_m": 0.3}
            for s in (0, 1) for label, ate in (("default", 0.1 + s), ("default_zhang", 0.4))]
    lines = seeds_table(rows, [1], [0, 1], ["default", "default_zhang"], TARGETS)
    lili, zhang = lines[2:]
    assert lili.startswith("| 1 | `default` | 0.100 / 0.300 | 1.100 / 0.300 | 0.600 / 0.300 |")
    assert lili.endswith("1 of 2 |")  # seed 1's ATE misses the 0.25 m target
    assert zhang.startswith("| 1 | `default_zhang` |") and zhang.endswith("0 of 2 |")


def _row(config, seed, start, final, repeat=0):
    return {"config": config, "seed": seed, "start": start, "repeat": repeat, "final_m": final,
            "ate_m": final / 2}


def test_paired_differences_against_the_first_configuration():
    rows = [_row("default", 0, 70.0, 2.0), _row("default", 0, 70.0, 4.0, repeat=1),
            _row("default", 1, 70.0, 1.0), _row("default", 2, 70.0, 5.0),
            _row("other", 0, 70.0, 1.0), _row("other", 1, 70.0, 2.0),
            _row("other", 2, 70.0, 1.0)]
    lines = paired_table(rows, ["default", run_label("config/other.yaml")])
    (line,) = lines[2:]
    # windows: (3 - 1), (1 - 2), (5 - 1) -> mean +1.67, default further off in 2 of 3
    assert line.startswith("| `other` | 3 | +1.67 | 2 of 3 |")
    assert 0.0 < float(line.split("|")[5]) <= 1.0


def test_reuse_takes_only_runs_of_the_same_settings():
    settings = {"trial": 1, "resolution": "32x256", "threads": 1}
    stored = {**settings, "runs": [_row("default", 0, 70.0, 1.0), _row("default", 1, 70.0, 2.0)]}
    key = ("seed", "start", "config", "repeat")

    def wanted(seeds, repeats=1):
        return {(s, 70.0, "default", r) for s in seeds for r in range(repeats)}

    assert len(matching_runs(stored, settings, wanted([0, 1]), key)) == 2
    assert len(matching_runs(stored, settings, wanted([1]), key)) == 1
    assert matching_runs(stored, settings, wanted([0, 1, 2]), key) is None
    assert matching_runs(stored, settings, wanted([0, 1], repeats=2), key) is None
    assert matching_runs(stored, {**settings, "threads": 0}, wanted([0, 1]), key) is None
