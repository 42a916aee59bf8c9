"""l1 sparsification of an orthonormal basis (the paper's Eq. "sparsification").

Given a basis ``B`` (k rows, orthonormal, in the scaled twist space), find the orthogonal
``T`` (k x k) minimising ``||T B||_1``; ``T B`` spans the same subspace with as few non-zero
components as possible, e.g. for a plane two pure in-plane translations and the pure rotation
about the normal. ``T`` is parametrised as ``expm(skew(theta))`` (reflections only flip row signs
and do not change the l1 norm); the non-smooth |x| is replaced by ``sqrt(x^2 + eps^2)`` and the
problem is solved by BFGS from several deterministic starts, keeping the best.

``T`` only mixes the rows, so the subspace is never changed; only the choice of basis inside it.

Gradient: for k = 2 and 3 (the usual degenerate dimensions) ``expm`` of the skew matrix and its
derivative are evaluated in closed form (Rodrigues: ``S^2 = -phi^2 I`` on the plane of ``S``), so
BFGS gets an exact gradient without finite differences and without ``scipy.linalg.expm`` (a
LAPACK call per evaluation). k >= 4 uses an eigen-decomposition of the skew matrix and finite
differences.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

_EPS = 1e-6


def _skew(theta: np.ndarray, k: int) -> np.ndarray:
    A = np.zeros((k, k))
    A[np.triu_indices(k, 1)] = theta
    return A - A.T


def _expm_skew(S: np.ndarray) -> np.ndarray:
    """``expm(S)`` of a real skew-symmetric ``S`` via the Hermitian matrix ``-i S`` (numpy only)."""
    w, V = np.linalg.eigh(-1j * S)
    return np.real((V * np.exp(1j * w)) @ V.conj().T)


def _rodrigues_coefficients(phi2: float) -> tuple[float, float, float, float]:
    """``a = sin(p)/p``, ``b = (1 - cos p)/p^2`` and their derivatives divided by p
    (``da/dp / p``, ``db/dp / p``) at ``p = sqrt(phi2)``, with series near 0."""
    if phi2 < 1e-6:
        return (1.0 - phi2 / 6.0 + phi2**2 / 120.0,
                0.5 - phi2 / 24.0 + phi2**2 / 720.0,
                -1.0 / 3.0 + phi2 / 30.0,
                -1.0 / 12.0 + phi2 / 180.0)
    p = np.sqrt(phi2)
    s, c = np.sin(p), np.cos(p)
    return (s / p, (1.0 - c) / phi2, (p * c - s) / (phi2 * p), (p * s - 2.0 * (1.0 - c)) / (phi2 * phi2))


def _rotation(theta: np.ndarray, k: int) -> np.ndarray:
    """``expm(skew(theta))`` (k x k)."""
    S = _skew(np.asarray(theta, dtype=float), k)
    if k > 3:
        return _expm_skew(S)
    a, b, _, _ = _rodrigues_coefficients(float(np.dot(theta, theta)))
    return np.eye(k) + a * S + b * (S @ S)


def _l1(B: np.ndarray) -> float:
    return float(np.sum(np.abs(B)))


def _cost_and_gradient(B: np.ndarray):
    """Smoothed l1 cost of ``expm(skew(theta)) B`` and its exact gradient (k = 2, 3)."""
    k = B.shape[0]
    n = k * (k - 1) // 2
    iu = np.triu_indices(k, 1)
    E = np.zeros((n, k, k))  # dS / dtheta_m
    E[np.arange(n), iu[0], iu[1]] = 1.0
    E[np.arange(n), iu[1], iu[0]] = -1.0
    eye = np.eye(k)

    def fun(theta: np.ndarray) -> tuple[float, np.ndarray]:
        S = np.einsum("m,mij->ij", theta, E)
        S2 = S @ S
        a, b, da, db = _rodrigues_coefficients(float(np.dot(theta, theta)))
        X = (eye + a * S + b * S2) @ B
        r = np.sqrt(X * X + _EPS**2)
        G = (X / r) @ B.T  # d cost / d R
        dR = (da * theta[:, None, None] * S + a * E + db * theta[:, None, None] * S2
              + b * (E @ S + S @ E))
        return float(np.sum(r)), np.einsum("mij,ij->m", dR, G)

    return fun


def _best_plane_rotation(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Angle t minimising ``|cos t a + sin t b|_1 + |cos t b - sin t a|_1`` and its change of cost.

    Between the angles where one component of either row is zero, the cost is a positive
    sinusoid, hence concave: the exact minimum is at one of those (at most 2 n) angles.
    """
    cand = np.concatenate([[0.0], np.arctan2(-a, b), np.arctan2(b, a)])
    c, s = np.cos(cand)[:, None], np.sin(cand)[:, None]
    cost = np.abs(c * a + s * b).sum(axis=1) + np.abs(c * b - s * a).sum(axis=1)
    i = int(np.argmin(cost))
    return float(cand[i]), float(cost[i] - cost[0])


def _plane_descent(B: np.ndarray, tol: float = 1e-12, max_sweeps: int = 200) -> np.ndarray:
    """Exact l1 descent by plane (Givens) rotations of row pairs until no pair improves."""
    B = B.copy()
    k = B.shape[0]
    for _ in range(max_sweeps):
        gain = 0.0
        for i in range(k - 1):
            for j in range(i + 1, k):
                t, d = _best_plane_rotation(B[i], B[j])
                if d < -tol:
                    c, s = np.cos(t), np.sin(t)
                    B[i], B[j] = c * B[i] + s * B[j], c * B[j] - s * B[i]
                    gain -= d
        if gain <= tol:
            break
    return B


def _polish(B: np.ndarray) -> np.ndarray:
    """BFGS on the smoothed cost of ``expm(skew(theta)) B`` from theta = 0 (joint rotations
    the pairwise descent cannot make); returned only when it lowers the exact l1 norm."""
    k = B.shape[0]
    n = k * (k - 1) // 2
    if k <= 3:
        fun, jac = _cost_and_gradient(B), True
    else:
        def fun(theta: np.ndarray) -> float:
            return float(np.sum(np.sqrt((_rotation(theta, k) @ B) ** 2 + _EPS**2)))
        jac = None
    res = minimize(fun, np.zeros(n), jac=jac, method="BFGS", options={"gtol": 1e-9, "maxiter": 500})
    X = _rotation(res.x, k) @ B
    return X if _l1(X) < _l1(B) else B


def sparsify(basis: np.ndarray, starts: int = 8, seed: int = 0) -> np.ndarray:
    """Return an orthonormal basis of the same row space with (locally) minimal l1 norm.

    From ``starts`` deterministic starting rotations (the identity, then random ones) the exact
    l1 norm is descended by pairwise plane rotations (``_plane_descent``); the best result is
    polished by BFGS on the smoothed cost (``_polish``). For k = 2 the plane step alone is the
    exact global minimum.

    Rows are normalised, sign-fixed (largest-magnitude component positive) and ordered by the
    index of that component, so the output is deterministic.
    """
    B = np.asarray(basis, dtype=float)
    k = B.shape[0]
    if k == 0:
        return B.reshape(0, B.shape[1] if B.ndim == 2 else 6)
    if k > 1:
        n = k * (k - 1) // 2
        rng = np.random.default_rng(seed)
        best, best_cost = B, _l1(B)
        for s in range(starts if k > 2 else 1):
            theta0 = np.zeros(n) if s == 0 else rng.uniform(-np.pi, np.pi, n)
            X = _plane_descent(_rotation(theta0, k) @ B)
            if _l1(X) < best_cost - 1e-12:
                best, best_cost = X, _l1(X)
        B = _polish(best) if k > 2 else best
    B = B / np.linalg.norm(B, axis=1, keepdims=True)
    lead = np.argmax(np.abs(B), axis=1)
    B = B * np.sign(B[np.arange(k), lead])[:, None]
    order = np.lexsort((-np.abs(B[np.arange(k), lead]), lead))
    return B[order]
