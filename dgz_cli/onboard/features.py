"""27 physical features per node (paper Sec. III-C-2) and the activation mask.

Per node, for each primitive p ∈ (FLEX, ABD, ROT) over the actuated joints the node maps to p:
limits in primitive space (sign-corrected, mean over joints) (6), axis direction s·a in the
palm frame (9), velocity bounds ±v (6), damping (3); plus the link vector from the parent
node's anchor (3). Everything is divided by a recorded scale and clipped to [-1, 1]; inactive
primitives are zero.
"""

from __future__ import annotations

import math

import numpy as np

from dgz_cli.spec.models import PRIMITIVES, FeatureNormalization

NORMALIZATION = FeatureNormalization(limit=math.pi, velocity=10.0, damping=1.0, length=0.2,
                                     default_velocity=math.pi)


def node_features(rows: list[dict], axes: dict[str, np.ndarray], link_vector: np.ndarray,
                  norm: FeatureNormalization = NORMALIZATION) -> list[float]:
    """``rows``: M_h rows (joint, primitive, sign, lower, upper, velocity, damping) of one node;
    ``axes``: joint → unit axis in palm-frame coordinates; ``link_vector``: (3,) metres."""
    lim, axis, vel, damp = np.zeros(6), np.zeros(9), np.zeros(6), np.zeros(3)
    for k, p in enumerate(PRIMITIVES):
        mine = [r for r in rows if r["primitive"] == p]
        if not mine:
            continue
        lo = np.mean([min(r["sign"] * r["lower"], r["sign"] * r["upper"]) for r in mine])
        hi = np.mean([max(r["sign"] * r["lower"], r["sign"] * r["upper"]) for r in mine])
        lim[2 * k:2 * k + 2] = [lo / norm.limit, hi / norm.limit]
        a = np.sum([r["sign"] * axes[r["joint"]] for r in mine], axis=0)
        axis[3 * k:3 * k + 3] = a / max(np.linalg.norm(a), 1e-12)
        v = np.mean([r["velocity"] if r["velocity"] > 0 else norm.default_velocity for r in mine])
        vel[2 * k:2 * k + 2] = [-v / norm.velocity, v / norm.velocity]
        damp[k] = np.mean([r["damping"] for r in mine]) / norm.damping
    out = np.concatenate([lim, axis, vel, damp, np.asarray(link_vector) / norm.length])
    return [round(float(x), 6) + 0.0 for x in np.clip(out, -1.0, 1.0)]


def activation_mask(node_ids: list[str], rows: list[dict]) -> dict[str, list[int]]:
    mask = {n: [0, 0, 0] for n in node_ids}
    for r in rows:
        mask[r["node"]][PRIMITIVES.index(r["primitive"])] = 1
    return mask
