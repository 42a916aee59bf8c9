"""What LiLi's return check would change and save, from a traced odometry run.

A *trace* holds, per fresh detection, the displacement ratio of every perturbed
re-registration at each return check (``check_ratios``, one list per run, as
``DegeneracyResult.details["check_ratios"]`` records them when every run goes to
convergence), each run's final ratio (``final_ratios``) and the detector's
``tau_displacement``.
"""
from __future__ import annotations

__all__ = ["return_check_effect"]


def return_check_effect(trace: dict, ratio: float) -> dict:
    """What ``lili.return_ratio = ratio`` would have changed and saved on one trace: runs
    stopped, *crossings* (stopped although they end above ``tau_displacement``, so kept:
    the only way the check changes a subspace), detections changed, native ICP calls of runs
    to convergence and those the stops save."""
    tau = trace["tau_displacement"]
    runs = stopped = crossings = changed = calls_full = calls_saved = 0
    for det in trace["detections"]:
        changed_here = False
        for checks, final in zip(det["check_ratios"], det["final_ratios"]):
            runs += 1
            calls_full += len(checks) + 1  # a chunk before each check, and the last one
            first = next((k for k, c in enumerate(checks) if c < ratio), None)
            if first is None:
                continue
            stopped += 1
            calls_saved += len(checks) - first  # the chunks after the stopping check
            if final > tau:
                crossings += 1
                changed_here = True
        changed += changed_here
    return {"ratio": ratio, "detections": len(trace["detections"]), "runs": runs,
            "stopped": stopped, "crossings": crossings, "detections_changed": changed,
            "calls_full": calls_full, "calls_saved": calls_saved,
            "calls_saved_fraction": calls_saved / calls_full if calls_full else 0.0}
