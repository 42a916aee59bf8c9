"""``--backend ray``: the suite's jobs as Ray tasks, one task per (scenario, seed, method).

Each task runs on whichever node Ray schedules it (one CPU per task):

1. it checks that the node runs the same lili_odom as the driver (:func:`code_fingerprint`),
2. it resolves its bag on that node (:func:`node_bag`): a scenario's bag is simulated into the
   node's simulator cache (``--cache-dir``, else the node's ``$LILI_ODOM_SIM_CACHE``, else
   ``data/sim``) under a per-node file lock, so two tasks on one node never simulate the same
   bag (its content key is the simulator's cache key); users' bags (``--bags``) must be
   readable at the same path on every node,
3. it runs the job (:func:`lili_odom.suite.jobs.execute`) in a temporary directory of the node,
   native output going to the job's ``log.txt``, and returns the row with the job's files
   (:class:`TaskResult`); the driver writes those files to ``OUT/runs/...`` as the local backend
   would, so the driver's disk need not be shared with the nodes.

A job whose row carries an ``error`` raises :class:`JobFailed` in its task, so Ray retries it
once (``max_retries=1``, ``retry_exceptions=[JobFailed]``), as it does for a task whose worker
process died (a native abort, out of memory) or whose node left; after the second failure the
driver writes a failed row with the reason (:func:`failure_row`). The driver collects rows as
they finish (``ray.wait``, :class:`Collector`). :meth:`RayBackend.shutdown` with ``cancel``
(Ctrl-C) cancels every outstanding task (``ray.cancel(force=True)``); the runner then writes
the rows that finished.

Without ``address`` the backend starts a Ray instance on this machine (``jobs`` CPUs, no
dashboard, usage statistics off, every Ray server on the loopback interface only) and stops it
at shutdown; with ``address`` it joins that cluster (``ray start --head`` there) and leaves it
running.
"""
from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import hashlib
import logging
import os
import shutil
import socket
import tempfile
import threading
import time
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from lili_odom.suite.jobs import Job, error_row, execute

log = logging.getLogger(__name__)

#: Attempts of one job: the first run and one retry.
ATTEMPTS = 2
#: Files of a job larger than this are not sent back to the driver (named in its log.txt).
MAX_FILE_BYTES = 64 * 1024 * 1024
#: Environment of a Ray instance this backend starts itself: no usage statistics are sent, and
#: the node's address is the loopback one, so Ray's servers listen on 127.0.0.1 only.
LOCAL_RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


# ---------------------------------------------------------------------------- task side

class JobFailed(Exception):
    """Raised by a task whose job produced a failed row, so that Ray retries it; carries the
    row and the job's files (its log)."""

    def __init__(self, row: dict, files: dict[str, bytes] | None = None) -> None:
        super().__init__(row.get("error", "failed"))
        self.row = row
        self.files = files or {}

    def __reduce__(self):
        return (JobFailed, (self.row, self.files))


@dataclass
class TaskResult:
    """What a task sends back: the row, the job's files (``job/<relative path>`` for the job's
    directory, ``truth`` for the ground truth in TUM format), the node's host name and whether
    this task simulated the bag."""

    row: dict
    files: dict[str, bytes] = field(default_factory=dict)
    node: str = ""
    simulated: bool = False


def code_fingerprint() -> str:
    """Hash of the lili_odom sources and scenario files this process would run (16 hex digits):
    equal on two machines when they produce the same rows for the same job."""
    from lili_odom.suite.scenario import scenario_dir

    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]
    files = sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)
    try:
        files += sorted(Path(scenario_dir()).glob("*.yaml"))
    except (OSError, ValueError):
        pass
    for p in files:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def bag_key(spec) -> str | None:
    """The simulator's content key of a scenario bag (None for a user's bag)."""
    if spec.path is not None:
        return None
    from lili_odom.sim.generator import cache_key
    from lili_odom.suite.scenario import load_scenario, scenario_dir, scenario_request

    scenario = load_scenario(Path(scenario_dir()) / f"{spec.scenario}.yaml", measure=False)
    return cache_key(scenario_request(scenario, spec.seed, ci=spec.ci, resolution=spec.resolution))


def bag_cache_dir(spec) -> Path:
    """The simulator cache of this node for ``spec``."""
    from lili_odom.sim.generator import default_cache_dir

    return Path(spec.cache_dir) if spec.cache_dir else default_cache_dir()


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``path`` (created if needed) for the block; blocks while
    another process (or another open of the file) holds it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def node_bag(spec, *, key: str | None = None, resolve: Callable[[], Path] | None = None) -> tuple[Path, bool]:
    """The bag of ``spec`` on this node and whether this call simulated it.

    A scenario bag is looked up in the node's cache by its content ``key`` (default
    :func:`bag_key`) and simulated (``resolve``, default ``spec.resolve``) while holding the
    lock file ``<cache>/.<key>.lock``, so concurrent calls on one node simulate it once."""
    if spec.path is not None:
        return Path(spec.path), False
    key = key if key is not None else bag_key(spec)
    cache = bag_cache_dir(spec)
    resolve = resolve or (lambda: spec.resolve(progress=False, jobs=1))

    def cached() -> bool:
        return any(cache.glob(f"*_{key}/metadata.yaml"))

    if cached():
        return Path(resolve()), False
    with file_lock(cache / f".{key}.lock"):
        simulated = not cached()
        path = Path(resolve())
    return path, simulated


@contextlib.contextmanager
def _output_to(path: Path) -> Iterator[None]:
    """Send this process's stdout/stderr (native libraries print there) to ``path`` for the
    block, then restore them."""
    import sys

    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    saved = []
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        for target in (1, 2):
            saved.append((target, os.dup(target)))
            os.dup2(fd, target)
        os.close(fd)
    except OSError:
        pass
    try:
        yield
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        for target, copy in saved:
            os.dup2(copy, target)
            os.close(copy)


def _pack(job_dir: Path, truth: Path) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    skipped = []
    for p in sorted(job_dir.rglob("*")):
        if not p.is_file():
            continue
        rel = p.relative_to(job_dir).as_posix()
        if p.stat().st_size > MAX_FILE_BYTES:
            skipped.append(f"{rel} ({p.stat().st_size / 1e6:.0f} MB)")
            continue
        files[f"job/{rel}"] = p.read_bytes()
    if skipped:
        note = ("not sent to the driver (larger than "
                f"{MAX_FILE_BYTES // 2**20} MiB): {', '.join(skipped)}\n").encode()
        files["job/log.txt"] = files.get("job/log.txt", b"") + note
    if truth.exists():
        files["truth"] = truth.read_bytes()
    return files


def run_task(job: Job, fingerprint: str | None = None,
             run: Callable[[Job], dict] = execute) -> TaskResult:
    """The body of a suite task (see the module docstring): returns the job's result, raises
    :class:`JobFailed` when its row carries an ``error``."""
    node = socket.gethostname()
    mine = code_fingerprint() if fingerprint is not None else None
    if fingerprint is not None and mine != fingerprint:
        raise JobFailed(error_row(job, f"node {node} runs other lili_odom sources (fingerprint {mine}, "
                                       f"driver {fingerprint}): install the same version on every node"))
    workdir = Path(tempfile.mkdtemp(prefix="lili-odom-suite-"))
    try:
        job_dir = workdir / "job"
        job_dir.mkdir()
        local = dataclasses.replace(job, out_dir=str(job_dir), truth_path=str(workdir / "truth.tum"))
        simulated = False
        with _output_to(job_dir / "log.txt"):
            try:
                _, simulated = node_bag(job.bag)
            except KeyboardInterrupt:
                raise
            except Exception as exc:  # noqa: BLE001 - the job fails, not the worker
                row = error_row(job, f"bag: {type(exc).__name__}: {exc}")
            else:
                try:
                    row = run(local)
                except KeyboardInterrupt:
                    raise
                except Exception as exc:  # noqa: BLE001 - execute() itself never raises
                    row = error_row(job, f"{type(exc).__name__}: {exc}")
        files = _pack(job_dir, workdir / "truth.tum")
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    if row.get("error"):
        raise JobFailed(row, files)
    return TaskResult(row=row, files=files, node=node, simulated=simulated)


# ---------------------------------------------------------------------------- driver side

def write_files(job: Job, files: dict[str, bytes]) -> None:
    """Write a task's files where the local backend would have written them: ``job/...``
    under ``job.out_dir``, ``truth`` at ``job.truth_path`` (each through a temporary file)."""
    for name, data in files.items():
        if name == "truth":
            dest = Path(job.truth_path)
        elif name.startswith("job/"):
            rel = Path(name[4:])
            if rel.is_absolute() or ".." in rel.parts:
                continue
            dest = Path(job.out_dir) / rel
        else:
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, dest)


def _cause(exc: BaseException) -> BaseException:
    """The exception a task raised, out of Ray's wrapper (``RayTaskError.cause``)."""
    cause = getattr(exc, "cause", None)
    return cause if isinstance(cause, BaseException) else exc


def failure_row(job: Job, exc: BaseException, attempts: int = ATTEMPTS) -> tuple[dict, dict[str, bytes]]:
    """The row (and files) of a job whose task failed for good with ``exc``: the job's own
    failed row for :class:`JobFailed`, else a row naming what happened to the task."""
    cause = _cause(exc)
    if isinstance(cause, JobFailed):
        row = dict(cause.row)
        row["error"] = f"{row.get('error', 'failed')} (attempts: {attempts})"
        return row, cause.files
    name = type(cause).__name__
    if name in ("TaskCancelledError",):
        return error_row(job, "cancelled"), {}
    first = (str(cause).strip().splitlines() or [""])[0]
    if name in ("WorkerCrashedError", "NodeDiedError", "OutOfMemoryError", "ObjectLostError",
                "OwnerDiedError", "ActorDiedError", "LocalRayletDiedError"):
        reason = f"Ray task lost ({name}, attempts: {attempts}): {first}"
    else:
        reason = f"{name}: {first} (attempts: {attempts})"
    return error_row(job, reason), {}


class Collector:
    """Submits tasks (at most ``limit`` outstanding; None: all), waits for them as they finish
    and resolves each job's future with its row, after writing its files. Engine-agnostic:
    ``submit(job) -> handle``, ``wait(handles, timeout) -> finished handles``,
    ``get(handle) -> TaskResult`` (raises the task's failure) and ``cancel(handle)``."""

    def __init__(self, submit: Callable, wait: Callable, get: Callable, cancel: Callable,
                 limit: int | None = None, poll_s: float = 0.5) -> None:
        self._submit, self._wait, self._get, self._cancel = submit, wait, get, cancel
        self.limit = limit
        self.poll_s = poll_s
        self.queued: deque[tuple[Job, Future]] = deque()
        self.running: dict = {}
        self.simulated: dict[str, int] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def add(self, job: Job) -> Future:
        future: Future = Future()
        with self._lock:
            self.queued.append((job, future))
        self._start()
        return future

    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="suite-ray-collector", daemon=True)
            self._thread.start()

    def _fill(self) -> None:
        with self._lock:
            while self.queued and (self.limit is None or len(self.running) < self.limit):
                job, future = self.queued.popleft()
                if future.cancelled():
                    continue
                try:
                    handle = self._submit(job)
                except Exception as exc:  # noqa: BLE001 - a refused submission fails its job
                    future.set_result(error_row(job, f"submit: {type(exc).__name__}: {exc}"))
                    continue
                self.running[handle] = (job, future)

    def step(self, timeout: float) -> int:
        """Submit what may be submitted, wait up to ``timeout`` s, resolve the finished jobs;
        returns how many finished."""
        self._fill()
        with self._lock:
            handles = list(self.running)
        if not handles:
            return 0
        done = self._wait(handles, timeout)
        for h in done:
            with self._lock:
                job, future = self.running.pop(h)
            try:
                result = self._get(h)
                row, files = result.row, result.files
                if result.simulated:
                    self.simulated[result.node] = self.simulated.get(result.node, 0) + 1
            except Exception as exc:  # noqa: BLE001 - every failure becomes the job's row
                row, files = failure_row(job, exc)
            try:
                write_files(job, files)
            except OSError as exc:
                log.warning("%s: could not write the job's files: %s", job.label, exc)
            future.set_result(row)
        return len(done)

    def _loop(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                idle = not self.running and not self.queued
            if idle:
                time.sleep(0.05)
                continue
            try:
                self.step(self.poll_s)
            except Exception:  # noqa: BLE001 - keep collecting
                log.exception("collecting suite tasks")
                time.sleep(self.poll_s)

    def outstanding(self) -> int:
        with self._lock:
            return len(self.running) + len(self.queued)

    def cancel_all(self) -> None:
        """Stop collecting; cancel every outstanding task and future."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5 * self.poll_s + 5)
        with self._lock:
            running, queued = list(self.running.items()), list(self.queued)
            self.running.clear()
            self.queued.clear()
        for handle, (_, future) in running:
            with contextlib.suppress(Exception):
                self._cancel(handle)
            future.cancel()  # futures stay pending until their row arrives: no row is written
        for _, future in queued:
            future.cancel()

    def close(self) -> None:
        """Wait for every outstanding job, then stop the collecting thread."""
        while self.outstanding():
            time.sleep(0.1)
        self._stop.set()
        if self._thread is not None:
            self._thread.join()


class RayBackend:
    """One Ray task per job (see the module docstring).

    Args:
        address: Ray cluster to join (``ray start --head`` prints it; ``auto`` finds one
            started on this machine); None starts a Ray instance on this machine.
        jobs: CPUs of the instance started without ``address``; with ``address`` at most this
            many tasks outstanding (None: as many as the cluster schedules).
        num_cpus: CPUs each task asks of Ray (default 1).
        run: the job executor inside each task (default :func:`lili_odom.suite.jobs.execute`).
    """

    name = "ray"
    prepares_bags = False

    def __init__(self, address: str | None = None, jobs: int | None = None, num_cpus: float = 1,
                 run: Callable[[Job], dict] = execute, check_sources: bool = True) -> None:
        if address is None:  # read by Ray when it is imported
            for k, v in LOCAL_RAY_ENV.items():
                os.environ.setdefault(k, v)
        else:
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        try:
            import ray  # noqa: F401
        except ImportError as exc:
            raise RuntimeError("--backend ray needs Ray: pip install 'lili_odom[cluster]'") from exc
        self.address = address
        self.jobs = jobs
        self._started = False
        self._init(address, jobs)
        import ray

        self._fingerprint = code_fingerprint() if check_sources else None
        remote = ray.remote(_remote_task).options(num_cpus=num_cpus, max_retries=ATTEMPTS - 1,
                                                   retry_exceptions=[JobFailed])
        run_fn = run
        fingerprint = self._fingerprint
        self.collector = Collector(
            submit=lambda job: remote.remote(job, fingerprint, run_fn),
            wait=lambda refs, timeout: ray.wait(refs, num_returns=len(refs), timeout=timeout,
                                                fetch_local=True)[0] or [],
            get=ray.get,
            cancel=lambda ref: ray.cancel(ref, force=True),
            limit=jobs if address is not None else None)

    def _init(self, address: str | None, jobs: int | None) -> None:
        import ray

        if ray.is_initialized():
            return
        if address is None:
            _loopback_only()
            ray.init(num_cpus=max(1, int(jobs or 1)), include_dashboard=False,
                     log_to_driver=False, logging_level=logging.WARNING, configure_logging=False)
            self._started = True
            ip = ray.util.get_node_ip_address()
            if ip not in ("127.0.0.1", "::1", "localhost"):
                log.warning("the local Ray instance listens on %s, not only on the loopback interface", ip)
        else:
            ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING,
                     configure_logging=False)

    def submit(self, job: Job) -> "Future[dict]":
        return self.collector.add(job)

    def shutdown(self, cancel: bool = False) -> None:
        import ray

        try:
            if cancel:
                self.collector.cancel_all()
            else:
                self.collector.close()
        finally:
            if self.collector.simulated:
                log.info("bags simulated per node: %s", self.collector.simulated)
            if self._started:
                ray.shutdown()
                self._started = False


def _remote_task(job: Job, fingerprint: str | None, run: Callable[[Job], dict]) -> TaskResult:
    return run_task(job, fingerprint, run)


def _loopback_only() -> None:
    """Make a Ray that is already imported pick the loopback address for a node it starts
    (its constant is read from the environment at import time)."""
    import sys

    consts = sys.modules.get("ray._private.ray_constants")
    if consts is not None and hasattr(consts, "ENABLE_RAY_CLUSTER"):
        consts.ENABLE_RAY_CLUSTER = False
