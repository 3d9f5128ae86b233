"""M_h as index arrays in the spec's own orders, and the deploy start pose.

The action layout and how a normalized action becomes joint targets are the control contract's
(:mod:`dgz_cli.spec.contract`); :class:`MhMap` only lists, for every actuated joint (``spec.joints``
order), its node (``spec.nodes`` order), primitive column (FLEX, ABD, ROT), sign, and its position
among its node's joints (for the joint-mode ablation).
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.models import PRIMITIVES, HandSpec


class MhMap:
    def __init__(self, spec: HandSpec) -> None:
        index = spec.node_index()
        self.n_nodes = len(spec.nodes)
        self.node = np.array([index[r.node] for r in spec.joints], dtype=int)
        self.prim = np.array([PRIMITIVES.index(r.primitive.value) for r in spec.joints], dtype=int)
        self.sign = np.array([r.sign for r in spec.joints], dtype=float)
        self.slot = spec.joint_slots()


def start_pose(spec: HandSpec, overrides: dict[str, float] | None = None, base: np.ndarray | None = None) -> np.ndarray:
    """The pose the hand ramps to before the policy runs: ``base`` (L,) if given (the control contract's start pose,
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
