"""Run a fuzz campaign: every door's cases in worker subprocesses, outcomes counted.

A worker (:mod:`lili_odom.fuzz.worker`) runs a range of cases of one door and reports each one.
When it dies inside a case (a native abort: SIGABRT from Sophus, Eigen or GTSAM, a segfault,
``os._exit``) the case is counted as ``native_abort`` and a new worker resumes at the next
case; when a case runs past its door's time limit the worker's process group is killed, the
case is counted as ``hang`` and a new worker resumes. Every finding (see
:data:`lili_odom.fuzz.outcome.FINDINGS`) can be written as a reproducer script.
"""
from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from lili_odom.fuzz.doors import DOORS
from lili_odom.fuzz.outcome import ABORT, FINDINGS, HANG, STATUSES

ROOT = Path(__file__).resolve().parents[2]
STARTUP_S = 180.0  # a worker's import time limit (a loaded 2-core machine is slow)


@dataclass
class DoorPlan:
    """Cases ``[start, start + cases)`` of ``door``, with options for its ``run_case``."""

    door: str
    cases: int
    options: dict[str, Any] = field(default_factory=dict)
    start: int = 0
    timeout_s: float | None = None  # per case; None = the door's default


def _worker_command(door: str, seed: int, start: int, stop: int, options: dict) -> list[str]:
    return [sys.executable, "-m", "lili_odom.fuzz.worker", door, str(seed), str(start),
            str(stop), json.dumps(options)]


def _reader(stream, q: queue.Queue) -> None:
    for line in stream:
        q.put(line)
    q.put(None)


def _signal_name(code: int) -> str:
    if code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"


def run_range(door: str, seed: int, start: int, stop: int, options: dict | None = None,
              timeout_s: float | None = None,
              on_result: Callable[[dict], None] | None = None) -> list[dict]:
    """Run cases ``[start, stop)`` of ``door`` in workers; one result dict per case."""
    options = options or {}
    limit = timeout_s if timeout_s is not None else DOORS[door][2]
    results: list[dict] = []
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    i = start
    while i < stop:
        with tempfile.TemporaryFile(mode="w+") as err:
            proc = subprocess.Popen(_worker_command(door, seed, i, stop, options), cwd=ROOT,
                                    env=env, stdout=subprocess.PIPE, stderr=err, text=True,
                                    start_new_session=True)
            q: queue.Queue = queue.Queue()
            threading.Thread(target=_reader, args=(proc.stdout, q), daemon=True).start()
            current, started_at = None, time.monotonic()
            deadline = started_at + STARTUP_S
            hung = False
            while True:
                try:
                    line = q.get(timeout=max(0.05, deadline - time.monotonic()))
                except queue.Empty:
                    if time.monotonic() < deadline:
                        continue
                    hung = True
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
                    break
                if line is None:
                    proc.wait()
                    break
                try:
                    msg = json.loads(line)
                except json.JSONDecodeError:
                    continue  # not a protocol line
                if not isinstance(msg, dict):
                    continue
                if "start" in msg:
                    current, started_at = msg["start"], time.monotonic()
                    deadline = started_at + limit
                else:
                    row = {"door": door, **msg}
                    results.append(row)
                    if on_result:
                        on_result(row)
                    i, current = msg["case"] + 1, None
            if current is None and not hung and proc.returncode == 0:
                break  # the worker finished its range
            err.seek(0)
            tail = " ".join(err.read()[-400:].split())
            if current is None:  # died or hung between cases (import, start-up)
                current = i
            status = HANG if hung else ABORT
            detail = (f"no answer within {limit:g} s" if hung
                      else f"{_signal_name(proc.returncode)}: {tail}")
            row = {"door": door, "case": current, "status": status, "detail": detail,
                   "seconds": round(time.monotonic() - started_at, 3), "error_type": "",
                   "input": ""}
            results.append(row)
            if on_result:
                on_result(row)
            i = current + 1
    return results


def run_door(plan: DoorPlan, seed: int, jobs: int = 1,
             on_result: Callable[[dict], None] | None = None) -> list[dict]:
    """All cases of one door, split into ``jobs`` contiguous ranges run at once."""
    jobs = max(1, min(jobs, plan.cases))
    bounds = [plan.start + plan.cases * k // jobs for k in range(jobs + 1)]
    lock = threading.Lock()

    def locked(row: dict) -> None:
        if on_result:
            with lock:
                on_result(row)

    with ThreadPoolExecutor(jobs) as pool:
        parts = list(pool.map(lambda k: run_range(plan.door, seed, bounds[k], bounds[k + 1],
                                                  plan.options, plan.timeout_s, locked),
                              range(jobs)))
    return sorted((r for part in parts for r in part), key=lambda r: r["case"])


def summarize(rows: list[dict], wall_s: float) -> dict:
    """Counts per status, documented error types and time of one door's results."""
    status = Counter(r["status"] for r in rows)
    return {"cases": len(rows), "wall_s": round(wall_s, 1),
            "case_s_mean": round(sum(r.get("seconds", 0.0) for r in rows) / max(len(rows), 1), 4),
            **{s: status.get(s, 0) for s in STATUSES},
            "error_types": dict(Counter(r.get("error_type") or "" for r in rows
                                        if r["status"] == "documented_error").most_common())}


def reproducer(row: dict, seed: int, options: dict) -> str:
    """A script that replays the case of ``row`` in a fresh process."""
    opts = "".join(f", {k}={v!r}" for k, v in options.items())

    def text(key: str) -> str:  # safe inside the docstring
        return str(row.get(key) or "").replace("\\", "/").replace('"""', "'''")

    return (f'"""Fuzz finding: door {row["door"]}, seed {seed}, case {row["case"]}: '
            f'{row["status"]}.\n\n'
            f'{text("detail")}\n\nInput: {text("input")}\n\n'
            f'Run from the repository root: python <this file> (a native abort ends it with a '
            f'signal).\n"""\n'
            "import os\nimport sys\n\nsys.path.insert(0, os.getcwd())\n\n"
            "from lili_odom.fuzz.doors import run_case  # noqa: E402\n\n"
            f'print(run_case("{row["door"]}", {seed}, {row["case"]}{opts}))\n')


def run_campaign(plans: list[DoorPlan], seed: int, jobs: int = 1,
                 reproducer_dir: Path | None = None, progress: bool = True) -> dict:
    """Run every plan; returns ``{"seed", "doors": {door: summary}, "findings": [...]}``."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, \
        TimeElapsedColumn

    report: dict[str, Any] = {"seed": seed, "jobs": jobs, "doors": {}, "findings": []}
    bar = Progress(TextColumn("{task.description:<10}"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("{task.fields[findings]} findings"), TimeElapsedColumn(),
                   disable=not progress)
    t_start = time.monotonic()
    with bar:
        tasks = {p.door: bar.add_task(p.door, total=p.cases, findings=0) for p in plans}
        for plan in plans:
            found = 0

            done = 0

            def advance(row: dict, task=tasks[plan.door], plan=plan) -> None:
                nonlocal found, done
                found += row["status"] in FINDINGS
                done += 1
                bar.update(task, advance=1, findings=found)
                if not progress and (done % max(1, plan.cases // 10) == 0 or done == plan.cases):
                    print(f"{plan.door}: {done}/{plan.cases} cases, {found} findings, "
                          f"{time.monotonic() - t_start:.0f} s", file=sys.stderr, flush=True)

            t0 = time.monotonic()
            rows = run_door(plan, seed, jobs, advance)
            report["doors"][plan.door] = {"options": plan.options,
                                          **summarize(rows, time.monotonic() - t0)}
            for row in rows:
                if row["status"] not in FINDINGS:
                    continue
                finding = {k: row.get(k, "") for k in ("door", "case", "status", "error_type",
                                                       "detail")}
                finding["input"] = row.get("input") or ""
                if reproducer_dir is not None:
                    reproducer_dir.mkdir(parents=True, exist_ok=True)
                    path = reproducer_dir / f"{plan.door}_{row['case']}.py"
                    path.write_text(reproducer(row, seed, plan.options))
                    finding["reproducer"] = path.name
                report["findings"].append(finding)
    report["wall_s"] = round(time.monotonic() - t_start, 1)
    report["cases"] = sum(d["cases"] for d in report["doors"].values())
    report["totals"] = {s: sum(d[s] for d in report["doors"].values()) for s in STATUSES}
    return report
