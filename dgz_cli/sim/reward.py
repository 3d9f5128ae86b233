"""Reward terms of paper Sec. III-C-4, each returned separately so they can be logged.

r = w_dis·r_dis + w_contact·r_contact + w_force·r_force + w_reg·r_reg + w_pen·r_pen with
r_dis = −Σ_i ‖d_i‖ (m), r_contact = Σ_i c_i, r_force = −Σ_i max(0, f_i − f0)² (f in units of
force_scale), r_reg = −‖Δq‖ (rad), r_pen = −Σ_i ‖(1 − m_i) ⊙ α_i‖² (α the policy's primitive output).

An optional term that is not in the paper (weight 0 by default): r_lift = clip(rise / lift_height, 0, 1)
after the grasp phase, rise being the object's height above its settled start. The paper's terms
reward contact but nothing that needs the object to go up with the hand; r_lift does.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.envconfig import RewardWeights

TERMS = ("dis", "contact", "force", "reg", "pen", "lift")


def reward_terms(d: np.ndarray, contact: np.ndarray, force: np.ndarray, dq: np.ndarray, alpha: np.ndarray,
                 mask: np.ndarray, node_valid: np.ndarray, f0: float, rise: np.ndarray | None = None,
                 lifting: np.ndarray | None = None, lift_height: float = 0.5) -> dict[str, np.ndarray]:
    """Unweighted terms, each (B,). d (B,N,3) m; contact (B,N) bool; force (B,N) scaled; dq (B,L) rad
    (zero-padded); alpha (B,N,3); mask (B,N,3); node_valid (B,N) bool; rise (B,) m and lifting (B,) bool
    (after the grasp phase) for r_lift, which is 0 without them."""
    v = node_valid.astype(np.float64)
    lift = (np.zeros(d.shape[0]) if rise is None or lifting is None
            else np.clip(rise / lift_height, 0.0, 1.0) * lifting)
    return {
        "dis": -(np.linalg.norm(d, axis=-1) * v).sum(-1),
        "contact": (contact * v).sum(-1),
        "force": -((np.maximum(0.0, force - f0) ** 2) * v).sum(-1),
        "reg": -np.linalg.norm(dq, axis=-1),
        "pen": -((((1.0 - mask) * alpha) ** 2).sum(-1) * v).sum(-1),
        "lift": lift,
    }


def total(terms: dict[str, np.ndarray], w: RewardWeights, use_pen: bool = True) -> np.ndarray:
    r = w.dis * terms["dis"] + w.contact * terms["contact"] + w.force * terms["force"] + w.reg * terms["reg"]
    if w.lift:
        r = r + w.lift * terms["lift"]
    return r + (w.pen * terms["pen"] if use_pen else 0.0)


GRASPXL_TERMS = ("dis", "contact", "force", "objvel", "lift", "success", "push", "residual", "displace")


def graspxl_terms(d: np.ndarray, contact: np.ndarray, force: np.ndarray, node_weight: np.ndarray,
                  v_rel: np.ndarray, rise: np.ndarray, lifting: np.ndarray, success: np.ndarray, pushed: np.ndarray,
                  lift_height: float, residual_sq: np.ndarray | None = None,
                  displacement: np.ndarray | None = None, push_limit: float = 0.3) -> dict[str, np.ndarray]:
    """Unweighted terms of the GraspXL-code reward (see ``GraspXLReward``), each (B,). d (B,N,3) m; contact
    (B,N) bool; force (B,N) in units of force_scale; node_weight (B,N) (0 on padding); v_rel (B,3) m/s the
    object's velocity relative to the palm (the object's own before the lift); rise (B,) m; lifting,
    success, pushed (B,) bool; residual_sq (B,) the mean squared policy action over its active dims (0 if None);
    displacement (B,) m the object's distance from where it settled, counted only while not ``lifting``
    (0 if None)."""
    wsum = np.maximum(node_weight.sum(-1), 1e-9)
    return {
        "dis": -(np.linalg.norm(d, axis=-1) * node_weight).sum(-1) / wsum,
        "contact": (contact * node_weight).sum(-1) / wsum,
        "force": (np.minimum(force, 1.0) * node_weight).sum(-1) / wsum,
        "objvel": -(v_rel ** 2).sum(-1),
        "lift": np.clip(rise / lift_height, 0.0, 1.0) * lifting,
        "success": success.astype(np.float64),
        "push": -pushed.astype(np.float64),
        "residual": -(np.zeros(d.shape[0]) if residual_sq is None else residual_sq),
        "displace": -(np.zeros(d.shape[0]) if displacement is None
                      else np.minimum(displacement, push_limit) / push_limit * ~lifting),
    }


def graspxl_total(terms: dict[str, np.ndarray], w) -> np.ndarray:
    """Weighted sum with the weights of a ``GraspXLReward`` (``push`` is weighted by its penalty)."""
    return (w.dis * terms["dis"] + w.contact * terms["contact"] + w.force * terms["force"] + w.objvel * terms["objvel"]
            + w.lift * terms["lift"] + w.success * terms["success"] + w.push_penalty * terms["push"]
            + w.residual * terms["residual"] + w.displace * terms["displace"])
