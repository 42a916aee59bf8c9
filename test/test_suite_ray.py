"""``--backend ray``: the backend-independent pieces (task body, bag lock, row collection, retry
bookkeeping) without Ray, then, when Ray is installed, the suite on a local Ray instance
(two CI pieces, rows equal to the local backend's), retries of failing jobs and lost workers,
and cancellation."""
from __future__ import annotations

import json
import math
import os
import threading
import time
from concurrent.futures import CancelledError
from pathlib import Path

import pytest

from lili_odom.suite.jobs import ROW_KEYS, BagSpec, Job, empty_row, error_row
from lili_odom.suite.ray_backend import (Collector, JobFailed, TaskResult, failure_row, node_bag,
                                         run_task, write_files)


def _job(tmp_path: Path, method: str = "m", bag: Path | None = None, scenario: str = "s") -> Job:
    run_dir = tmp_path / "out" / "runs" / scenario / "seed0"
    bag = bag or tmp_path / "bag"
    bag.mkdir(exist_ok=True)
    return Job(scenario=scenario, split="tuning", kind="tunnel", seed=0, method=method,
               bag=BagSpec(path=str(bag)), out_dir=str(run_dir / method),
               truth_path=str(run_dir / "truth.tum"))


def _ok_row(job: Job, ate: float = 0.5) -> dict:
    row = empty_row(job)
    row.update(ate_m=ate, rpe_pct=1.0, final_m=0.2, distance_m=10.0, scans=3, wall_s=1.0)
    return row


# ---------------------------------------------------------------------------- without Ray

def test_run_task_returns_row_and_files_from_a_scratch_directory(tmp_path):
    job = _job(tmp_path)

    def run(local: Job) -> dict:
        assert local.out_dir != job.out_dir and local.truth_path != job.truth_path
        assert Path(local.bag.path) == Path(job.bag.path)
        (Path(local.out_dir) / "odometry").mkdir(parents=True)
        (Path(local.out_dir) / "odometry" / "a.mcap").write_bytes(b"mcap")
        Path(local.truth_path).write_text("0 0 0 0 0 0 0 1\n")
        os.write(1, b"native output\n")
        return _ok_row(local)

    result = run_task(job, None, run)
    assert isinstance(result, TaskResult) and not result.simulated
    assert result.row == _ok_row(job)
    assert result.files["job/odometry/a.mcap"] == b"mcap"
    assert result.files["truth"] == b"0 0 0 0 0 0 0 1\n"
    assert b"native output" in result.files["job/log.txt"]
    write_files(job, result.files)
    assert (Path(job.out_dir) / "odometry" / "a.mcap").read_bytes() == b"mcap"
    assert Path(job.truth_path).read_text() == "0 0 0 0 0 0 0 1\n"
    assert b"native output" in (Path(job.out_dir) / "log.txt").read_bytes()


def test_run_task_raises_job_failed_for_failed_and_raising_jobs(tmp_path):
    job = _job(tmp_path)
    with pytest.raises(JobFailed) as info:
        run_task(job, None, lambda local: error_row(local, "no pose estimated"))
    assert info.value.row["error"] == "no pose estimated" and "job/log.txt" in info.value.files

    def boom(local: Job) -> dict:
        raise RuntimeError("native failure")

    with pytest.raises(JobFailed) as info:
        run_task(job, None, boom)
    assert info.value.row["error"] == "RuntimeError: native failure"
    with pytest.raises(JobFailed) as info:
        run_task(job, "0000000000000000", lambda local: _ok_row(local))
    assert "other lili_odom sources" in info.value.row["error"]


def test_job_failed_survives_pickling(tmp_path):
    import pickle

    exc = JobFailed(error_row(_job(tmp_path), "x"), {"job/log.txt": b"y"})
    back = pickle.loads(pickle.dumps(exc))
    assert back.row == exc.row and back.files == exc.files and str(back) == "x"


def test_node_bag_simulates_once_per_node(tmp_path):
    """Concurrent tasks of one node needing the same bag: one simulates, the others wait for
    the lock and find it in the cache."""
    spec = BagSpec(scenario="building", seed=0, ci=True, cache_dir=str(tmp_path / "cache"))
    calls = []

    def resolve() -> Path:
        bag = tmp_path / "cache" / "building_ci_32x512_seed0_abc123"
        if not (bag / "metadata.yaml").exists():
            calls.append(1)
            time.sleep(0.3)
            bag.mkdir(parents=True)
            (bag / "metadata.yaml").write_text("x")
        return bag

    results = []
    threads = [threading.Thread(target=lambda: results.append(node_bag(spec, key="abc123", resolve=resolve)))
               for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1
    assert sorted(simulated for _, simulated in results) == [False, False, True]
    assert node_bag(spec, key="abc123", resolve=resolve)[1] is False
    user = BagSpec(path=str(tmp_path / "mine"))
    assert node_bag(user) == (tmp_path / "mine", False)


class WorkerCrashedError(Exception):
    """Stands in for Ray's exception of the same name."""


class _FakeEngine:
    """Tasks whose outcomes are given up front; ``wait`` returns one finished task per call."""

    def __init__(self, outcomes: dict[str, object]) -> None:
        self.outcomes = outcomes
        self.submitted: list[str] = []
        self.cancelled: list[str] = []
        self.max_outstanding = 0
        self._open: list[str] = []

    def submit(self, job: Job) -> str:
        self.submitted.append(job.method)
        self._open.append(job.method)
        self.max_outstanding = max(self.max_outstanding, len(self._open))
        return job.method

    def wait(self, handles, timeout):
        ready = [h for h in handles if self.outcomes.get(h) is not None][:1]
        for h in ready:
            self._open.remove(h)
        return ready

    def get(self, handle):
        out = self.outcomes[handle]
        if isinstance(out, BaseException):
            raise out
        return out

    def cancel(self, handle):
        self.cancelled.append(handle)


def test_collector_rows_failures_and_limit(tmp_path):
    jobs = {m: _job(tmp_path, m) for m in ("ok", "failed", "crashed")}
    engine = _FakeEngine({
        "ok": TaskResult(_ok_row(jobs["ok"]), {"job/estimate_base.tum": b"e", "truth": b"t"}, "n1", True),
        "failed": JobFailed(error_row(jobs["failed"], "no pose estimated"), {"job/log.txt": b"abort"}),
        "crashed": WorkerCrashedError("The worker died unexpectedly\nmore"),
    })
    c = Collector(engine.submit, engine.wait, engine.get, engine.cancel, limit=1, poll_s=0.01)
    futures = {m: c.add(j) for m, j in jobs.items()}
    rows = {m: f.result(timeout=10) for m, f in futures.items()}
    c.close()
    assert engine.max_outstanding == 1 and engine.submitted == ["ok", "failed", "crashed"]
    assert rows["ok"] == _ok_row(jobs["ok"])
    assert (Path(jobs["ok"].out_dir) / "estimate_base.tum").read_bytes() == b"e"
    assert Path(jobs["ok"].truth_path).read_bytes() == b"t"
    assert c.simulated == {"n1": 1}
    assert rows["failed"]["error"] == "no pose estimated (attempts: 2)"
    assert (Path(jobs["failed"].out_dir) / "log.txt").read_bytes() == b"abort"
    assert rows["crashed"]["error"] == ("Ray task lost (WorkerCrashedError, attempts: 2): "
                                        "The worker died unexpectedly")
    for m in ("failed", "crashed"):
        assert set(ROW_KEYS) <= set(rows[m]) and rows[m]["ate_m"] is None


def test_collector_cancel_all_drops_outstanding_jobs(tmp_path):
    jobs = [_job(tmp_path, f"m{i}") for i in range(3)]
    engine = _FakeEngine({})  # nothing ever finishes
    c = Collector(engine.submit, engine.wait, engine.get, engine.cancel, limit=2, poll_s=0.01)
    futures = [c.add(j) for j in jobs]
    deadline = time.time() + 10
    while len(engine.submitted) < 2 and time.time() < deadline:
        time.sleep(0.01)
    c.cancel_all()
    assert sorted(engine.cancelled) == ["m0", "m1"]
    for f in futures:
        with pytest.raises(CancelledError):
            f.result(timeout=1)
    assert c.outstanding() == 0


def test_failure_row_names_other_errors(tmp_path):
    job = _job(tmp_path)
    row, files = failure_row(job, ValueError("bad\nsecond line"))
    assert row["error"] == "ValueError: bad (attempts: 2)" and files == {}


# ---------------------------------------------------------------------------- with Ray

def _ci_scenarios() -> list[str]:
    from lili_odom.suite.runner import SuiteRequest, select_scenarios

    try:
        return [s.name for s in select_scenarios(SuiteRequest(out=".", preset="ci"))]
    except (ValueError, OSError):
        return []


@pytest.fixture(scope="module")
def ray_instance():
    """One local Ray instance (2 CPUs, loopback only) shared by the Ray tests."""
    from lili_odom.suite.ray_backend import LOCAL_RAY_ENV, _loopback_only

    for k, v in LOCAL_RAY_ENV.items():
        os.environ.setdefault(k, v)
    try:
        import ray
    except ImportError:
        pytest.skip("Ray is not installed (pip install 'lili_odom[cluster]')")
    _loopback_only()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        assert ray.util.get_node_ip_address() == "127.0.0.1"
        yield ray
    finally:
        ray.shutdown()


def test_ray_ci_suite_matches_local_backend(ray_instance, tmp_path):
    """Two CI pieces with the wheel odometry (deterministic) on both backends: the same rows
    (metrics equal apart from timings), ``backend`` recorded, reports and run files written."""
    from lili_odom.suite.backends import LocalBackend
    from lili_odom.suite.ray_backend import RayBackend
    from lili_odom.suite.runner import SuiteRequest, run_suite

    names = _ci_scenarios()[:2]
    if len(names) < 2:
        pytest.skip("fewer than two scenarios with a CI piece")
    docs = {}
    for name, backend in (("ray", RayBackend(jobs=2)), ("local", LocalBackend(jobs=2))):
        out = tmp_path / name
        request = SuiteRequest(out=out, preset="ci", scenarios=names, methods=["wheels"])
        docs[name] = run_suite(request, backend, progress=False)
        assert json.loads((out / "suite.json").read_text()) == docs[name]
        assert docs[name]["backend"] == name
        for n in names:
            assert (out / "runs" / n / "seed0" / "truth.tum").stat().st_size > 0
            assert (out / "runs" / n / "seed0" / "wheels" / "estimate_base.tum").stat().st_size > 0
            assert (out / f"{n}.png").exists()
        assert "Backend: " + name in (out / "suite.md").read_text()
    rows = {k: {(r["scenario"], r["seed"], r["method"]): r for r in d["rows"]} for k, d in docs.items()}
    assert set(rows["ray"]) == set(rows["local"]) and len(rows["ray"]) == 2
    for key, r in rows["ray"].items():
        local = rows["local"][key]
        assert "error" not in r, r.get("error")
        assert list(r) == list(local)
        for k in ("split", "kind", "scans", "degenerate_fraction"):
            assert r[k] == local[k], k
        for k in ("ate_m", "rpe_pct", "final_m", "distance_m"):
            assert math.isfinite(r[k]) and r[k] == pytest.approx(local[k], rel=1e-9, abs=1e-12), k


def _fake_job(tmp_path: Path, method: str) -> Job:
    return _job(tmp_path, method, bag=tmp_path / "userbag", scenario="fake")


def test_ray_retries_failed_jobs_and_lost_workers_once(ray_instance, tmp_path):
    """A job failing once then succeeding, a worker dying once, a job always failing: the first
    two give rows, the last a failed row after two attempts."""
    from lili_odom.suite.ray_backend import RayBackend

    marks = tmp_path / "marks"
    marks.mkdir()

    def flaky(job: Job) -> dict:
        attempts = marks / job.method
        with open(attempts, "a") as f:
            f.write("x")
        n = len(attempts.read_text())
        if job.method == "fails_once" and n == 1:
            return error_row(job, "transient failure")
        if job.method == "dies_once" and n == 1:
            os._exit(1)
        if job.method == "always_fails":
            raise RuntimeError(f"broken (attempt {n})")
        row = empty_row(job)
        row.update(ate_m=0.1 * n, scans=n)
        return row

    backend = RayBackend(jobs=2, run=flaky)
    futures = {m: backend.submit(_fake_job(tmp_path, m)) for m in ("fails_once", "dies_once", "always_fails")}
    rows = {m: f.result(timeout=300) for m, f in futures.items()}
    backend.shutdown()
    assert rows["fails_once"]["scans"] == 2 and "error" not in rows["fails_once"]
    assert rows["dies_once"]["scans"] == 2 and "error" not in rows["dies_once"]
    assert rows["always_fails"]["error"] == "RuntimeError: broken (attempt 2) (attempts: 2)"
    assert {m: len((marks / m).read_text()) for m in rows} == {"fails_once": 2, "dies_once": 2,
                                                                "always_fails": 2}
    log = Path(_fake_job(tmp_path, "always_fails").out_dir) / "log.txt"
    assert log.exists()


def test_ray_cancel_stops_outstanding_tasks(ray_instance, tmp_path):
    from lili_odom.suite.ray_backend import RayBackend

    started = tmp_path / "started"

    def slow(job: Job) -> dict:
        started.write_text("1")
        time.sleep(120)
        (tmp_path / "finished").write_text("1")
        return empty_row(job)

    backend = RayBackend(jobs=2, run=slow)
    future = backend.submit(_fake_job(tmp_path, "slow"))
    deadline = time.time() + 120
    while not started.exists() and time.time() < deadline:
        time.sleep(0.2)
    assert started.exists()
    t0 = time.time()
    backend.shutdown(cancel=True)
    assert time.time() - t0 < 30
    with pytest.raises(CancelledError):
        future.result(timeout=1)
    time.sleep(1)
    assert not (tmp_path / "finished").exists()


def test_ray_ctrl_c_keeps_finished_rows(ray_instance, tmp_path):
    """Ctrl-C during a suite on Ray: the finished row is written, the running task is
    cancelled, the reports are written and the interrupt reaches the caller."""
    import signal

    from lili_odom.suite.ray_backend import RayBackend
    from lili_odom.suite.runner import SuiteRequest, run_suite

    bag = tmp_path / "userbag"
    bag.mkdir()

    def run(job: Job) -> dict:
        if job.method == "slow":
            (tmp_path / "slow_started").write_text("1")
            time.sleep(120)
            (tmp_path / "slow_finished").write_text("1")
        row = empty_row(job)
        row.update(ate_m=0.25, scans=1)
        return row

    out = tmp_path / "suite"

    def interrupt_when_ready() -> None:
        deadline = time.time() + 120
        while time.time() < deadline:
            try:
                quick_done = len(json.loads((out / "suite.json").read_text())["rows"]) == 1
            except (OSError, ValueError, KeyError):
                quick_done = False
            if quick_done and (tmp_path / "slow_started").exists():
                break
            time.sleep(0.2)
        os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C sends

    threading.Thread(target=interrupt_when_ready, daemon=True).start()
    request = SuiteRequest(out=out, bags=[bag], methods=["quick", "slow"])
    with pytest.raises(KeyboardInterrupt):
        run_suite(request, RayBackend(jobs=2, run=run), progress=False)
    doc = json.loads((out / "suite.json").read_text())
    assert doc["backend"] == "ray" and doc["wall_time_s"] is not None
    assert [(r["method"], r["ate_m"]) for r in doc["rows"]] == [("quick", 0.25)]
    assert (out / "suite.md").exists()
    time.sleep(1)
    assert not (tmp_path / "slow_finished").exists()
