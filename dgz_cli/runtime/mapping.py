"""M_h: per-node primitive actions → joint deltas, in the spec's own orders.

An action is ``6 + 3·N_nodes`` numbers: the wrist command (Δp x, y, z in m; Δθ x, y, z in rad) followed by
α, an (N_nodes, 3) array in ``spec.nodes`` order with columns FLEX, ABD, ROT, flattened row by row.
For every actuated joint j (``spec.joints`` order): Δq_j = sign_j · α[node_j, primitive_j].
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.models import PRIMITIVES, HandSpec

WRIST_DIM = 6


class MhMap:
    def __init__(self, spec: HandSpec) -> None:
        index = spec.node_index()
        self.n_nodes = len(spec.nodes)
        self.node_ids = [n.id for n in spec.nodes]
        self.node = np.array([index[r.node] for r in spec.joints], dtype=int)
        self.prim = np.array([PRIMITIVES.index(r.primitive.value) for r in spec.joints], dtype=int)
        self.sign = np.array([r.sign for r in spec.joints], dtype=float)
        self.mask = np.array([spec.activation_mask.get(n.id, [0, 0, 0]) for n in spec.nodes], dtype=float)
        self.action_dim = WRIST_DIM + 3 * self.n_nodes

    def split(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(action, dtype=float)
        return a[:WRIST_DIM], a[WRIST_DIM:].reshape(self.n_nodes, 3)

    def join(self, wrist: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(wrist, dtype=float), np.asarray(alpha, dtype=float).reshape(-1)])

    def delta_q(self, alpha: np.ndarray) -> np.ndarray:
        alpha = np.asarray(alpha, dtype=float).reshape(self.n_nodes, 3)
        return self.sign * alpha[self.node, self.prim]


def start_pose(spec: HandSpec, overrides: dict[str, float] | None = None, base: np.ndarray | None = None) -> np.ndarray:
    """The pose the hand ramps to before the policy runs: ``base`` (L,) if given (the thumb-open pose of
    :mod:`dgz_cli.runtime.pregrasp`), else every joint at 0 clipped into its limits (the URDF zero is the
    flat open hand on the shipped hands); then the hand file's ``start_pose`` entries, clipped."""
    lo = np.array([j.lower for j in spec.joints], dtype=float)
    hi = np.array([j.upper for j in spec.joints], dtype=float)
    q = spec.rest_pose() if base is None else np.clip(np.asarray(base, dtype=float), lo, hi)
    names = [j.joint for j in spec.joints]
    for name, value in (overrides or {}).items():
        if name not in names:
            from dgz_cli.spec.errors import DgzError

            raise DgzError(f"start_pose names joint '{name}', which is not in spec '{spec.name}'",
                           "use joint names from the spec's joints[].joint")
        i = names.index(name)
        q[i] = min(max(float(value), lo[i]), hi[i])
    return q
