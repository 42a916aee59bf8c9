"""The degeneracy detector in a process of its own, next to the odometry's main loop.

A LiLi detection (12 perturbed KISS-ICP re-registrations) costs several scan registrations,
and the native calls hold Python's GIL, so a thread would not run it alongside the main loop.
``DetectionWorker`` runs the detector in a child process that keeps a *mirror* of the local
map: the pipeline sends it every map change (``update_map``, ``reset``) and every detection
request in the order it makes them, and the child applies them in that order, so a detection
runs against exactly the map the pipeline had when it asked (KISS-ICP's ``VoxelHashMap``
updated with the same points and poses, :func:`lili_odom.pipeline.scan_matcher.insert_scan`).
Only the timing differs from a detection in the main loop: the result comes back while later
scans are processed (``lili_odom.pipeline.detection_schedule``: when it is applied).

Requests travel through ``multiprocessing`` queues, whose feeder thread sends in the
background, so a large map update never blocks the main loop while the child is busy. The
child is started from a ``forkserver`` (``spawn`` where there is none), never forked from the
caller, whose native thread pools (TBB, DDS) must not be forked.

When the child dies or does not answer within ``timeout_s``, the worker reports it
(``alive`` False) and the pipeline detects in its main loop from then on.

Frames and units as in :mod:`lili_odom.pipeline.scan_matcher`: points in the LiDAR frame [m],
poses ``T_odom_lidar`` 4x4.
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import pickle
import queue
import threading
import time
import weakref
from typing import Any, Callable

import numpy as np

from lili_odom.degeneracy.result import DegeneracyResult

log = logging.getLogger(__name__)

__all__ = ["DetectionWorker", "PENDING"]

#: What :meth:`DetectionWorker.result` returns when the result did not arrive in time.
PENDING = object()


def _context():
    try:
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload([__name__, "kiss_icp.mapping", "lili_odom.degeneracy.lili",
                                    "lili_odom.degeneracy.hessian"])
        return ctx
    except ValueError:  # no forkserver on this platform
        return mp.get_context("spawn")


def _serve(requests, replies, make_detector, voxel: float, max_range: float,
           max_points_per_voxel: int) -> None:
    """The child's loop: apply map changes and answer detection requests in order."""
    from kiss_icp.mapping import VoxelHashMap

    from lili_odom.degeneracy.reference import ReferenceMap
    from lili_odom.pipeline.scan_matcher import insert_scan

    def new_map() -> ReferenceMap:
        return ReferenceMap(VoxelHashMap(voxel, max_range, max_points_per_voxel), voxel,
                            max_points_per_voxel)

    reference = new_map()
    detector = make_detector()
    while True:
        message = requests.get()
        kind = message[0]
        if kind == "stop":
            return
        if kind == "reset":
            reference = new_map()
        elif kind == "update":
            insert_scan(reference, message[1], message[2])
        elif kind == "detect":
            seq, points, guess, optimized = message[1:]
            try:
                result = detector.detect(reference, points, guess, optimized_pose=optimized)
            except Exception as exc:  # reported to the caller, which detects itself then
                result = exc
            replies.put((seq, result))


def _stop(process, requests) -> None:
    """Ask the child to stop, then make sure it did (finaliser: no reference to the worker)."""
    try:
        if process.is_alive():
            requests.put(("stop",))
        requests.close()  # pending data is not waited for (``cancel_join_thread``)
    except (OSError, ValueError):
        pass
    process.join(timeout=2.0)
    if process.is_alive():
        process.terminate()
        process.join(timeout=2.0)


class DetectionWorker:
    """A detector object run in a child process against a mirror of the local map.

    Args:
        make_detector: a picklable callable that returns the detector, an object with
            ``detect(reference, scan, initial_pose, optimized_pose=)`` (e.g.
            ``functools.partial(LiliDetector, config)``); called in the child.
        voxel, max_range, max_points_per_voxel: the local map's parameters (as the
            ``ScanMatcher``'s ``VoxelHashMap``) [m, m, points].
        timeout_s: longest wait for a result before the child counts as hung [s].
    """

    def __init__(self, make_detector: Callable[[], Any], voxel: float, max_range: float,
                 max_points_per_voxel: int, timeout_s: float = 10.0) -> None:
        self.timeout_s = float(timeout_s)
        self._args = (make_detector, float(voxel), float(max_range), int(max_points_per_voxel))
        self._process = None
        self._finalizer = None
        self._starter: threading.Thread | None = None
        self._start_error = ""
        self.alive = True
        self.failure = ""
        try:
            pickle.dumps(self._args)  # what the child gets: fail here, not in the thread
            ctx = _context()
            self._requests, self._replies = ctx.Queue(), ctx.Queue()
            # a dead child cannot drain the pipe: never wait for the feeder at close or exit
            self._requests.cancel_join_thread()
            self._process = ctx.Process(target=_serve, args=(self._requests, self._replies,
                                                             *self._args),
                                        name="lili_odom_detector", daemon=True)
        except Exception as exc:  # noqa: BLE001 - e.g. an unpicklable factory: no process
            self._process = None
            self._fail(f"could not start the detector process: {exc}")
            return
        # Starting the child waits for the forkserver to import the detector's modules (most
        # of a second): done in a thread, so the caller goes on meanwhile. Requests queue up
        # until the child reads them.
        self._starter = threading.Thread(target=self._start, name="lili_odom_detector_start",
                                         daemon=True)
        self._starter.start()

    def _start(self) -> None:
        try:
            self._process.start()
        except Exception as exc:  # noqa: BLE001 - e.g. no forkserver process
            self._start_error = f"could not start the detector process: {exc}"
            return
        self._finalizer = weakref.finalize(self, _stop, self._process, self._requests)

    def _started(self, wait: bool) -> bool:
        """False when the child could not be started (the worker is then closed); with
        ``wait`` False, True while it is still starting."""
        starter = self._starter
        if starter is not None:
            if not wait and starter.is_alive():
                return True
            starter.join()
            self._starter = None
        if self._start_error:
            self._fail(self._start_error)
            return False
        return True

    def ready(self) -> bool:
        """Wait until the child process runs; False when it could not be started or the
        worker is closed."""
        return self.alive and self._started(wait=True)

    def _send(self, message: tuple) -> None:
        if not (self.alive and self._started(wait=False)):
            return
        try:
            self._requests.put(message)
        except (OSError, ValueError) as exc:
            self._fail(f"request not sent: {exc}")

    def reset(self) -> None:
        """The local map was cleared."""
        self._send(("reset",))

    def update_map(self, points: np.ndarray, pose: np.ndarray) -> None:
        """``points`` (LiDAR frame) were inserted into the local map at ``pose``."""
        self._send(("update", np.ascontiguousarray(points, dtype=np.float64),
                    np.asarray(pose, dtype=np.float64)))

    def submit(self, seq: int, points: np.ndarray, guess: np.ndarray,
               optimized: np.ndarray) -> bool:
        """Ask for the detection of ``points`` registered at ``optimized`` from ``guess``
        against the map as it is now; False when the worker is not available."""
        if not self.alive:
            return False
        self._send(("detect", int(seq), np.ascontiguousarray(points, dtype=np.float64),
                    np.asarray(guess, dtype=np.float64),
                    np.asarray(optimized, dtype=np.float64)))
        return self.alive

    def result(self, seq: int, wait_s: float | None = None) -> DegeneracyResult | object | None:
        """The result of request ``seq``; earlier, abandoned results are discarded.

        Args:
            seq: the request's sequence number.
            wait_s: longest wait for it [s]; None waits until it arrives (or ``timeout_s``).

        Returns:
            The result; :data:`PENDING` when it did not arrive within ``wait_s`` (ask again
            later); None when the detection raised (``failure`` says why), or when the child
            died or did not answer within ``timeout_s`` (the worker is then closed and
            ``alive`` is False).
        """
        if not (self.alive and self._started(wait=wait_s is None)):
            return None
        now = time.monotonic()
        deadline = now + self.timeout_s
        give_up = None if wait_s is None else now + max(0.0, float(wait_s))
        while True:
            poll = 0.2 if give_up is None else max(0.0, min(0.2, give_up - time.monotonic()))
            try:
                got, result = self._replies.get(timeout=poll)
            except queue.Empty:
                starting = self._starter is not None and self._starter.is_alive()
                if not starting and not self._process.is_alive():
                    self._fail("the detector process died")
                    return None
                if give_up is not None and time.monotonic() >= give_up:
                    return PENDING
                if time.monotonic() > deadline:
                    self._fail(f"no detection result within {self.timeout_s:g} s")
                    return None
                continue
            except (OSError, EOFError, ValueError) as exc:
                self._fail(f"reply not received: {exc}")
                return None
            if got < seq:
                continue
            if got != seq:
                self._fail("replies out of order")
                return None
            if isinstance(result, Exception):
                self.failure = f"detection failed in the detector process: {result!r}"
                return None
            return result

    def _fail(self, reason: str) -> None:
        self.alive = False
        self.failure = reason
        log.warning("%s: detecting in the main loop from now on", reason)
        self.close()

    def close(self) -> None:
        """Stop the child process (idempotent)."""
        if self._starter is not None:
            self._starter.join()
            self._starter = None
        if self._finalizer is not None:
            self._finalizer()
