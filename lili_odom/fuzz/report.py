"""Markdown report of a campaign (the dict :func:`lili_odom.fuzz.campaign.run_campaign` returns)."""
from __future__ import annotations

from lili_odom.fuzz.outcome import STATUSES

_HEAD = {"clean": "clean", "documented_error": "documented error", "other_exception":
         "other exception", "nonfinite_output": "non-finite output", "invalid_output":
         "invalid output", "stalled": "stopped after a fault", "native_abort": "native abort",
         "hang": "hang"}

_WHAT = {
    "clouds": "PointCloud2 content -> `parse_cloud` (documented: `CloudFormatError`)",
    "api": "`Scan` / `ImuSample` / `WheelSample` -> `OdometryPipeline` (documented: "
           "`PipelineInputError`)",
    "feeder": "ROS messages on any topic -> `MessageFeeder` (documented: none, nothing may "
              "escape)",
    "bags": "broken bags and parameter files -> `lili-odom run` (documented: `UserError`, exit 2)",
    "detect": "cloud / pose files and options -> `lili-odom detect` (documented: `UserError`, "
              "exit 2)",
    "sequences": "faulted 200-scan runs (CI bag + a 50-scan loop) -> feeder + pipeline "
                 "(`lili`, `none`)",
}


def render(report: dict, command: str) -> str:
    lines = [
        "# Fuzz campaign",
        "",
        f"Seed {report['seed']}, {report['cases']} cases, {report['wall_s'] / 60:.1f} min wall "
        f"time with {report['jobs']} worker(s) at a time. Reproduce with:",
        "",
        "```",
        command,
        "```",
        "",
        "Each case runs in a worker subprocess; a worker that dies inside a case counts a "
        "native abort, a case past its time limit counts a hang, and a new worker resumes at "
        "the next case. Statuses: *clean* = handled (result, counted skip or rejection); "
        "*documented error* = the door's documented exception with a one-line message; "
        "*stopped after a fault* = no output for valid input after the bad input.",
        "",
        "| door | what | cases | " + " | ".join(_HEAD[s] for s in STATUSES) + " | s/case |",
        "|---|---|---:|" + "---:|" * len(STATUSES) + "---:|",
    ]
    for door, d in report["doors"].items():
        lines.append(f"| {door} | {_WHAT.get(door, '')} | {d['cases']} | "
                     + " | ".join(str(d[s]) for s in STATUSES) + f" | {d['case_s_mean']:.3f} |")
    t = report["totals"]
    lines.append(f"| **all** | | **{report['cases']}** | "
                 + " | ".join(f"**{t[s]}**" for s in STATUSES) + " | |")
    lines += ["", "Documented errors by type:", ""]
    for door, d in report["doors"].items():
        types = ", ".join(f"`{k or '?'}` {v}" for k, v in d["error_types"].items()) or "none"
        lines.append(f"- {door}: {types}")
    lines += ["", "## Findings", ""]
    if not report["findings"]:
        lines.append("None: no native abort, hang, undocumented exception, non-finite or "
                     "invalid output, and no pipeline that stopped producing output.")
    for f in report["findings"]:
        repro = f" (`{f['reproducer']}`)" if f.get("reproducer") else ""
        lines.append(f"- {f['door']} case {f['case']}: **{f['status']}**{repro}: "
                     f"{f['detail']} — input: {f['input']}")
    return "\n".join(lines) + "\n"
