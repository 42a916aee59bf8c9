"""lili_odom.evaluation.return_check: the counting of stops, crossings and saved ICP calls."""
from lili_odom.evaluation.return_check import return_check_effect


def test_counts_stops_crossings_and_saved_calls():
    trace = {"tau_displacement": 0.2, "detections": [
        # run 1 comes back (stops at its 2nd check under 0.1); run 2 slides (never below);
        # run 3 dips to 0.12 and ends kept at 0.5: a crossing for ratios above 0.12 only
        {"check_ratios": [[0.5, 0.08, 0.02, 0.01], [0.9, 0.95], [0.3, 0.12, 0.4]],
         "final_ratios": [0.005, 0.97, 0.5], "dimension": 1},
        {"check_ratios": [[]], "final_ratios": [0.9], "dimension": 1},  # converged at once
    ]}
    low = return_check_effect(trace, 0.1)
    counts = (low["runs"], low["stopped"], low["crossings"], low["detections_changed"])
    assert counts == (4, 1, 0, 0)
    assert low["calls_full"] == 5 + 3 + 4 + 1
    assert low["calls_saved"] == 3  # the chunks after run 1's second check
    high = return_check_effect(trace, 0.15)
    assert (high["stopped"], high["crossings"], high["detections_changed"]) == (2, 1, 1)
    assert high["calls_saved"] == 3 + 2
