"""Run one method of the suite over a bag and return its trajectory in base_link.

* Our methods (:data:`OUR_METHODS`: ``none``, ``zhang``, ``hessian``, ``lili``) run through the
  offline runner (:func:`lili_odom.evaluation.runner.run_bag`), i.e. the node's own pipeline,
  with the suite's configuration (``--config`` file, then ``--set`` overrides) and
  ``pipeline.method`` set to the method. The runner's files land in the job's directory.
* Peers (:data:`lili_odom.suite.peers.PEERS`) run through :mod:`lili_odom.suite.peers`.

Every method's wall time covers reading the bag and the odometry alike.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lili_odom.suite.jobs import Job
from lili_odom.suite.peers import PEERS

OUR_METHODS = ("none", "zhang", "hessian", "lili")
ALL_METHODS = OUR_METHODS + PEERS
#: PyPI distribution each peer needs (``pip install lili_odom[peers]``)
PEER_PACKAGES = {"kiss": "kiss_icp", "genz": "genz_icp", "rko": "rko_lio", "wheels": None}


@dataclass
class MethodRun:
    """A method's trajectory (base_link poses in its odometry frame) and the bag's truth."""

    stamps: np.ndarray
    poses: np.ndarray
    truth_stamps: np.ndarray
    truth_poses: np.ndarray
    scans: int
    wall_s: float
    degenerate_fraction: float | None


def peer_available(method: str) -> bool:
    """True when the peer's package imports (always True for our methods and ``wheels``)."""
    module = PEER_PACKAGES.get(method)
    if module is None:
        return True
    try:
        importlib.import_module(module)
    except Exception:  # noqa: BLE001 - a broken install counts as missing
        return False
    return True


def node_config(config_path: str | None, overrides: tuple[tuple[str, str], ...] = (),
                truth_topic: str | None = None):
    """The configuration of our odometry: defaults, the parameter file, then ``--set``
    overrides (``name=value``; a name not found at the top level is looked up under
    ``pipeline.``). Raises ValueError naming a bad parameter."""
    import yaml

    from lili_odom.config import apply_params, flatten, load_config

    config = load_config(Path(config_path) if config_path else None)
    known = flatten(config)
    params = {}
    for name, value in overrides:
        name = name.strip()
        full = name if name in known else f"pipeline.{name}"
        params[full] = yaml.safe_load(value) if isinstance(value, str) else value
    if truth_topic:
        params["ground_truth_topic"] = truth_topic
    if params:
        apply_params(config, params)
    return config


def run_method(job: Job, bag: Path) -> MethodRun:
    """Run ``job.method`` over ``bag``; raises on failure (the caller makes it a row)."""
    config = node_config(job.config_path, job.overrides, job.truth_topic)
    if job.method in OUR_METHODS:
        return _run_ours(job, bag, config)
    if job.method in PEERS:
        return _run_peer(job, bag, config)
    raise ValueError(f"unknown method {job.method!r} (known: {', '.join(ALL_METHODS)})")


def _run_ours(job: Job, bag: Path, config) -> MethodRun:
    import shutil

    from lili_odom.evaluation.runner import run_bag

    config.pipeline.method = job.method
    config.validate()
    out = Path(job.out_dir)
    if (out / "odometry").exists():  # a rerun into the same directory replaces the old run
        shutil.rmtree(out / "odometry")
    run = run_bag(bag, config, out, rpe_segment=job.rpe_segment_m, progress=False)
    truth = sorted(run.truth, key=lambda x: x[0])
    dims = np.asarray(run.dimensions)
    return MethodRun(
        stamps=run.stamps, poses=run.poses,
        truth_stamps=np.array([s for s, _ in truth]),
        truth_poses=np.array([T for _, T in truth]).reshape(-1, 4, 4),
        scans=len(run.estimates), wall_s=float(run.summary["wall_time_s"]),
        degenerate_fraction=float(np.mean(dims > 0)) if len(dims) else None)


def _run_peer(job: Job, bag: Path, config) -> MethodRun:
    from lili_odom.suite.peers.inputs import Context

    package = PEER_PACKAGES.get(job.method)
    if package is not None and not peer_available(job.method):
        raise RuntimeError(f"peer {job.method!r} needs the Python package {package!r} "
                           f"(pip install 'lili_odom[peers]')")
    module = importlib.import_module(f"lili_odom.suite.peers.{job.method}")
    ctx = Context(config=config, kind=job.kind, truth_topic=job.truth_topic)
    r = module.run(bag, ctx)
    return MethodRun(r.stamps, r.poses, r.truth_stamps, r.truth_poses, r.scans, r.wall_s,
                     r.degenerate_fraction)
