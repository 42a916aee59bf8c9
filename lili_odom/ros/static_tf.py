"""Compose static transforms (from ``/tf_static``) into one frame-to-frame transform.

Pure Python. ``T_a_b`` maps points of frame ``b`` into frame ``a``; the transforms form a tree
(edges may be walked in either direction, using the inverse when walking child -> parent).
"""
from __future__ import annotations

from collections import deque
from typing import Mapping

import numpy as np

__all__ = ["lookup"]


def _inverse(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    R = T[:3, :3]
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def lookup(transforms: Mapping[tuple[str, str], np.ndarray], target: str, source: str
           ) -> np.ndarray | None:
    """``T_target_source`` from ``{(parent, child): T_parent_child}``, or None if unconnected."""
    if target == source:
        return np.eye(4)
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (parent, child), T in transforms.items():
        T = np.asarray(T, dtype=np.float64)
        edges.setdefault(parent, []).append((child, T))
        edges.setdefault(child, []).append((parent, _inverse(T)))
    best: dict[str, np.ndarray] = {target: np.eye(4)}  # T_target_frame
    queue = deque([target])
    while queue:
        frame = queue.popleft()
        for nxt, T in edges.get(frame, []):
            if nxt not in best:
                best[nxt] = best[frame] @ T
                if nxt == source:
                    return best[nxt]
                queue.append(nxt)
    return None
