"""Vectorized observation math over a batch of B slots, padded to N nodes / L joints / P points.

Node features (paper Sec. III-C-1, Supp. S2), hand-centric (palm frame: f, l, n), fixed scales:
    [d (3), θ (3), θ̇ (3), c (1), f (1), finger one-hot (6), node-type one-hot (6)]  → NODE_DIM = 23
    d   node → nearest object-surface point, clipped to norm ≤ distance_clip, divided by it
    θ   sign-corrected joint angles per primitive axis (mean over the node's joints), / π
    θ̇   the same for velocities, / 10 rad/s, clipped to [-1, 1]
    c   contact flag; f contact normal force / force_scale, clipped to [0, 5]
Global features: [Δp_target (3) / 0.5 m, v_wrist (3) / 1 m/s, ω_wrist (3) / 5 rad/s,
    v_obj (3) / 1 m/s, ω_obj (3) / 5 rad/s, lift flag (1)], clipped to [-1, 1]  → GLOBAL_DIM = 16
"""

from __future__ import annotations

import numpy as np

NODE_DIM = 23
GLOBAL_DIM = 16
COL_D, COL_THETA, COL_THETA_DOT, COL_CONTACT, COL_FORCE, COL_FINGER, COL_TYPE = 0, 3, 6, 9, 10, 11, 17


def node_positions(body_pos: np.ndarray, body_rot: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(B,N,3) world anchors from body poses (B,N,3), (B,N,3,3) and body-frame points (B,N,3)."""
    return body_pos + np.einsum("bnij,bnj->bni", body_rot, point)


def nearest_surface(nodes: np.ndarray, obj_pos: np.ndarray, obj_rot: np.ndarray, cloud: np.ndarray,
                    pre: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(B,N,3) world vectors from each node to its nearest cloud point.

    nodes (B,N,3) world; obj_pos (B,3); obj_rot (B,3,3); cloud (B,P,3) in the object frame;
    ``pre`` = ``cloud_terms(cloud)``, to pass when the clouds do not change between calls.
    """
    local = np.einsum("bni,bij->bnj", nodes - obj_pos[:, None], obj_rot)  # world → object frame
    cloud_sq, cloud_m2 = cloud_terms(cloud) if pre is None else pre
    # |c|² − 2 x·c (+ |x|², the same for every c, dropped); scaling by −2 is exact: = |c|² − 2 (x @ cᵀ)
    d2 = local @ cloud_m2.transpose(0, 2, 1)  # (B,N,P)
    d2 += cloud_sq
    idx = d2.argmin(-1)
    b, p = cloud.shape[:2]
    nearest = cloud.reshape(-1, 3)[idx + (np.arange(b) * p)[:, None]]  # (B,N,3)
    return np.einsum("bij,bnj->bni", obj_rot, nearest - local)


def cloud_terms(cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-cloud constants of :func:`nearest_surface`: (B,1,P) squared norms and −2 × the points (B,P,3)."""
    return (cloud ** 2).sum(-1)[:, None, :], -2.0 * cloud


def to_frame(vec: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Express world vectors (B,...,3) in frames whose world rotations are (B,3,3)."""
    if vec.ndim == 2:
        return np.einsum("bij,bi->bj", rot, vec)
    return np.einsum("bij,bni->bnj", rot, vec)


def clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(n, 1e-12))


def primitive_state(q: np.ndarray, proj: np.ndarray) -> np.ndarray:
    """(B,N,3) sign-corrected mean joint value per node and primitive; proj (B,N*3,L), q (B,L)."""
    b = q.shape[0]
    return np.einsum("bkl,bl->bk", proj, q).reshape(b, -1, 3)


def projection(joint_node: np.ndarray, joint_prim: np.ndarray, joint_sign: np.ndarray, n_nodes: int) -> np.ndarray:
    """(N*3, L) matrix averaging sign-corrected joints onto (node, primitive) axes."""
    w = np.zeros((n_nodes * 3, len(joint_node)))
    for j, (n, p, s) in enumerate(zip(joint_node, joint_prim, joint_sign)):
        w[3 * n + p, j] = s
    counts = np.abs(w).sum(1, keepdims=True)
    return w / np.maximum(counts, 1.0)


def node_features(d: np.ndarray, theta: np.ndarray, theta_dot: np.ndarray, contact: np.ndarray, force: np.ndarray,
                  finger: np.ndarray, node_type: np.ndarray, valid: np.ndarray, distance_clip: float,
                  force_scale: float, static: np.ndarray | None = None) -> np.ndarray:
    """Assemble (B,N,NODE_DIM) float32 node features; padded nodes are zero. ``static`` (B,N,12): the
    one-hot columns already masked (``static_features``), to pass when they do not change between calls.
    Each block is computed in float64, masked and rounded to float32 column-wise (the same numbers as
    concatenating in float64, masking and casting, without the (B,N,23) float64 temporaries)."""
    v = valid[..., None]
    x = np.empty(d.shape[:2] + (NODE_DIM,), dtype=np.float32)
    x[..., COL_D:COL_THETA] = clip_norm(d, distance_clip) / distance_clip * v
    x[..., COL_THETA:COL_THETA_DOT] = theta / np.pi * v
    x[..., COL_THETA_DOT:COL_CONTACT] = np.clip(theta_dot / 10.0, -1.0, 1.0) * v
    x[..., COL_CONTACT] = contact * valid
    x[..., COL_FORCE] = np.clip(force / force_scale, 0.0, 5.0) * valid
    x[..., COL_FINGER:] = static_features(finger, node_type, valid) if static is None else static
    return x


def static_features(finger: np.ndarray, node_type: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(B,N,12) float32: finger-class and node-type one-hots, zero on padded nodes."""
    x = np.concatenate([finger, node_type], axis=-1).astype(np.float64) * valid[..., None]
    return x.astype(np.float32)


def global_features(dp: np.ndarray, v_w: np.ndarray, w_w: np.ndarray, v_o: np.ndarray, w_o: np.ndarray,
                    lift: np.ndarray) -> np.ndarray:
    g = np.concatenate([dp / 0.5, v_w, w_w / 5.0, v_o, w_o / 5.0, lift[:, None].astype(np.float64)], axis=-1)
    return np.clip(g, -1.0, 1.0).astype(np.float32)


def rotation_delta(r_prev: np.ndarray, r_now: np.ndarray) -> np.ndarray:
    """(B,3) world rotation vectors of r_now · r_prevᵀ (small angles)."""
    d = np.einsum("bij,bkj->bik", r_now, r_prev)
    return 0.5 * np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], axis=-1)
