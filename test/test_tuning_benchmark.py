"""``python -m benchmarks.tuning``: refuses validation scenarios, and its table marks the best
configuration per row and averages the ATE in % of the distance."""
import math

import pytest

from benchmarks import tuning


def _doc(rows):
    return {"rows": rows}


def _row(scenario, method, ate, seed=0, distance=100.0, **extra):
    return {"scenario": scenario, "seed": seed, "method": method, "ate_m": ate,
            "distance_m": distance, **extra}


def test_validation_scenarios_are_refused(capsys):
    with pytest.raises(SystemExit, match="not in the tuning split"):
        tuning.main(["--scenarios", "airfield", "--out", "unused"])


def test_unknown_configuration_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="no such configuration file"):
        tuning.main(["--configs", "default", "nope.yaml", "--out", str(tmp_path)])


def test_report_marks_the_best_and_averages_the_percentages():
    results = {
        "default": _doc([_row("a", "lili", 0.2), _row("b", "lili", 1.0, distance=50.0)]),
        "other": _doc([_row("a", "lili", 0.4), _row("b", "lili", 0.5, distance=50.0)]),
    }
    wheels = _doc([_row("a", "wheels", 0.6), _row("b", "wheels", 0.7, distance=50.0)])
    text = tuning.report(results, wheels, "lili", "python -m benchmarks.tuning")
    lines = {l.split("|")[1].strip(): l for l in text.splitlines() if l.startswith("| ")}
    assert "**0.200 (0.20 %)**" in lines["a"] and "0.400 (0.40 %)" in lines["a"]
    assert "**0.500 (1.00 %)**" in lines["b"] and "1.000 (2.00 %)" in lines["b"]
    assert "0.600 (0.60 %)" in lines["a"]  # the wheels' column
    means = lines["**mean of the %**"]
    assert "1.10 %" in means and "0.70 %" in means


def test_a_failed_run_is_shown_and_not_averaged():
    results = {"default": _doc([_row("a", "lili", None, error="boom")])}
    text = tuning.report(results, {}, "lili", "cmd")
    assert "– (a run failed)" in text
    assert math.isnan(tuning._cell({"error": "x"})[0])


def test_repeats_report_the_median_and_the_range_and_average_the_medians():
    results = {
        "default": [_doc([_row("a", "lili", x)]) for x in (0.2, 0.6, 0.3)],
        "other": [_doc([_row("a", "lili", x)]) for x in (0.25, 0.25, 0.9)],
    }
    text = tuning.report(results, {}, "lili", "cmd")
    line = next(l for l in text.splitlines() if l.startswith("| a |"))
    assert "**0.250 (0.25 %)** [0.250-0.900]" in line
    assert "0.300 (0.30 %) [0.200-0.600]" in line
    means = next(l for l in text.splitlines() if l.startswith("| **mean"))
    assert "0.30 %" in means and "0.25 %" in means
    assert "3 runs per configuration" in text
    failed = {"default": [_doc([_row("a", "lili", 0.2)]), _doc([_row("a", "lili", None,
                                                                   error="x")])]}
    assert "– (a run failed)" in tuning.report(failed, {}, "lili", "cmd")


def test_repeats_must_be_positive(tmp_path):
    with pytest.raises(SystemExit, match="--repeats must be at least 1"):
        tuning.main(["--repeats", "0", "--out", str(tmp_path)])
