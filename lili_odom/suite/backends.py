"""Where suite jobs run. A backend turns a :class:`~lili_odom.suite.jobs.Job` into a future
of its row (``submit(job) -> Future[dict]``); the runner collects rows as they finish.

* :class:`LocalBackend` (``--backend local``): up to ``jobs`` jobs at a time on this machine,
  each in its own fresh, non-daemonic process (``spawn``; our odometry starts its background
  detector process in it, as ``lili-odom run`` does), so a native abort (KISS-ICP, GTSAM, a
  peer) or a crash ends only that job: it becomes a row with ``error`` naming the exit
  signal. A job's stdout/stderr (native libraries print there) go to ``<job dir>/log.txt``.

* :class:`~lili_odom.suite.ray_backend.RayBackend` (``--backend ray``): one Ray task per job
  on a Ray cluster or a Ray instance on this machine (``pip install 'lili_odom[cluster]'``).

A backend for a cluster implements the same two methods and sets ``prepares_bags`` False:
its tasks then resolve (simulate or fetch from their node's cache) their bag themselves via
``job.bag.resolve()``, which is keyed by content, so a bag is simulated at most once per node.
"""
from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Protocol

from lili_odom.suite.jobs import Job, error_row, execute

log = logging.getLogger(__name__)

BACKENDS = ("local", "ray")


class Backend(Protocol):
    """What the runner needs of a backend."""

    name: str
    #: True: the driver makes each bag before submitting its jobs (tasks share one disk).
    prepares_bags: bool

    def submit(self, job: Job) -> "Future[dict]":
        """Start ``job`` (or queue it); the future's result is the job's row (never raises
        for a failure of the job itself)."""
        ...

    def shutdown(self, cancel: bool = False) -> None:
        """Wait for the submitted jobs; with ``cancel`` drop queued ones and stop running ones."""
        ...


def _child_main(job: Job, conn, log_path: str) -> None:
    """Entry point of a job's process: run it, send its row back. Ctrl-C is the driver's to
    handle (it stops the job), so the job ignores SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    except OSError:
        pass
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    row = execute(job)
    conn.send(row)
    conn.close()


def _exit_reason(code: int | None) -> str:
    if code is None:
        return "job process did not finish"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        return f"job process killed by {name} (native crash or out of memory)"
    return f"job process exited with code {code} without a result"


class LocalBackend:
    """Up to ``jobs`` jobs at a time, one fresh process each (see module docstring).

    Args:
        jobs: jobs running at the same time.
        timeout_s: a job running longer is stopped and reported as failed (None: no limit).
    """

    name = "local"
    prepares_bags = True

    def __init__(self, jobs: int = 1, timeout_s: float | None = None) -> None:
        self.jobs = max(1, int(jobs))
        self.timeout_s = timeout_s
        self._pool = ThreadPoolExecutor(max_workers=self.jobs, thread_name_prefix="suite-job")
        self._ctx = multiprocessing.get_context("spawn")
        self._running: set = set()
        self._lock = threading.Lock()
        self._cancelled = threading.Event()

    def submit(self, job: Job) -> "Future[dict]":
        return self._pool.submit(self._run, job)

    def _run(self, job: Job) -> dict:
        if self._cancelled.is_set():
            return error_row(job, "cancelled")
        recv, send = self._ctx.Pipe(duplex=False)
        log_path = str(Path(job.out_dir) / "log.txt")
        # not daemonic: the odometry in it starts its background detector process, as
        # `lili-odom run` does (a daemonic process may not have children); the finally below
        # and shutdown() stop it
        proc = self._ctx.Process(target=_child_main, args=(job, send, log_path), daemon=False)
        with self._lock:
            proc.start()
            self._running.add(proc)
        send.close()
        try:
            waited = 0.0
            while not recv.poll(0.5):
                waited += 0.5
                if not proc.is_alive() and not recv.poll(0):
                    proc.join()
                    return error_row(job, _exit_reason(proc.exitcode))
                if self._cancelled.is_set():
                    proc.terminate()
                    return error_row(job, "cancelled")
                if self.timeout_s is not None and waited > self.timeout_s:
                    proc.terminate()
                    return error_row(job, f"timed out after {self.timeout_s:.0f} s")
            try:
                row = recv.recv()
            except (EOFError, OSError):
                proc.join()
                return error_row(job, _exit_reason(proc.exitcode))
            proc.join(timeout=30)
            return row
        finally:
            recv.close()
            if proc.is_alive():
                proc.kill()
                proc.join()
            with self._lock:
                self._running.discard(proc)

    def shutdown(self, cancel: bool = False) -> None:
        if cancel:
            self._cancelled.set()
            with self._lock:
                for proc in list(self._running):
                    if proc.is_alive():
                        proc.terminate()
        self._pool.shutdown(wait=True, cancel_futures=cancel)


def make_backend(name: str, jobs: int | None, timeout_s: float | None = None,
                 address: str | None = None) -> Backend:
    """The backend called ``name`` (:data:`BACKENDS`); ``address``: the Ray cluster of
    ``ray`` (None: a Ray instance on this machine with ``jobs`` CPUs)."""
    if name == "local":
        return LocalBackend(jobs=jobs or 1, timeout_s=timeout_s)
    if name == "ray":
        from lili_odom.suite.ray_backend import RayBackend

        return RayBackend(address=address, jobs=jobs)
    raise ValueError(f"unknown backend {name!r} (available: {', '.join(BACKENDS)})")
