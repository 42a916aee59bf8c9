"""l1 sparsification of an orthonormal basis (the paper's Eq. "sparsification").

Given a basis ``B`` (k rows, orthonormal, in the scaled twist space), find the orthogonal
``T`` (k x k) minimising ``||T B||_1``; ``T B`` spans the same subspace with as few non-zero
components as possible, e.g. for a plane two pure in-plane translations and the pure rotation
about the normal. ``T`` is parametrised as ``expm(skew(theta))`` (reflections only flip row signs
and do not change the l1 norm); the non-smooth |x| is replaced by ``sqrt(x^2 + eps^2)`` and the
problem is solved by BFGS from several deterministic starts, keeping the best.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm
from scipy.optimize import minimize

_EPS = 1e-6


def _rotation(theta: np.ndarray, k: int) -> np.ndarray:
    A = np.zeros((k, k))
    A[np.triu_indices(k, 1)] = theta
    return expm(A - A.T)


def _l1(B: np.ndarray) -> float:
    return float(np.sum(np.abs(B)))


def sparsify(basis: np.ndarray, starts: int = 8, seed: int = 0) -> np.ndarray:
    """Return an orthonormal basis of the same row space with (locally) minimal l1 norm.

    Rows are normalised, sign-fixed (largest-magnitude component positive) and ordered by the
    index of that component, so the output is deterministic.
    """
    B = np.asarray(basis, dtype=float)
    k = B.shape[0]
    if k == 0:
        return B.reshape(0, B.shape[1] if B.ndim == 2 else 6)
    if k > 1:
        n = k * (k - 1) // 2

        def cost(theta: np.ndarray) -> float:
            return float(np.sum(np.sqrt((_rotation(theta, k) @ B) ** 2 + _EPS**2)))

        rng = np.random.default_rng(seed)
        best_theta, best_cost = np.zeros(n), cost(np.zeros(n))
        for s in range(starts):
            theta0 = np.zeros(n) if s == 0 else rng.uniform(-np.pi, np.pi, n)
            res = minimize(cost, theta0, method="BFGS", options={"gtol": 1e-9, "maxiter": 500})
            if res.fun < best_cost:
                best_theta, best_cost = res.x, res.fun
        B = _rotation(best_theta, k) @ B
    B = B / np.linalg.norm(B, axis=1, keepdims=True)
    lead = np.argmax(np.abs(B), axis=1)
    B = B * np.sign(B[np.arange(k), lead])[:, None]
    order = np.lexsort((-np.abs(B[np.arange(k), lead]), lead))
    return B[order]
