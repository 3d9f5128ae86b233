"""Vectorized observation math over a batch of B slots, padded to N nodes / L joints / P points.

The column layout and the normalization scales are the control contract's
(:class:`dgz_cli.spec.contract.ObservationLayout`); this module only computes the blocks and writes
them where the layout says. Hand-centric quantities are expressed in the palm frame (f, l, n).
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.contract import ObservationLayout


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


def pd_error(targets: np.ndarray, q: np.ndarray, proj: np.ndarray, scale: float) -> np.ndarray:
    """(B,N,3) the finger targets' lead over the joints per primitive axis, / scale, clipped to [-1, 1];
    targets, q (B,L) rad; proj (B,N*3,L)."""
    return np.clip(primitive_state(targets - q, proj) / scale, -1.0, 1.0)


def projection(joint_node: np.ndarray, joint_prim: np.ndarray, joint_sign: np.ndarray, n_nodes: int) -> np.ndarray:
    """(N*3, L) matrix averaging sign-corrected joints onto (node, primitive) axes."""
    w = np.zeros((n_nodes * 3, len(joint_node)))
    for j, (n, p, s) in enumerate(zip(joint_node, joint_prim, joint_sign)):
        w[3 * n + p, j] = s
    counts = np.abs(w).sum(1, keepdims=True)
    return w / np.maximum(counts, 1.0)


def node_features(layout: ObservationLayout, valid: np.ndarray, static: np.ndarray, **blocks: np.ndarray) -> np.ndarray:
    """Assemble (B, N, node_dim) float32 node features; padded nodes are zero.

    ``blocks`` are the raw per-node quantities by block name: ``d`` (B,N,3) m, ``theta`` / ``theta_dot``
    (B,N,3) rad and rad/s, ``contact`` (B,N) bool, ``force`` (B,N) N; any other block of the layout is
    passed already normalized, (B,N) or (B,N,w). ``static`` (B,N,12): the finger and node-type one-hots,
    masked (:func:`static_features`). Each block is computed in float64, masked and rounded to float32
    column-wise (the same numbers as concatenating in float64, masking and casting)."""
    v = valid[..., None]
    x = np.empty(valid.shape + (layout.node_dim,), dtype=np.float32)
    for name, width in layout.node:
        col = layout.node_col(name)
        if name in ("finger", "node_type"):
            continue
        raw = blocks[name]
        if name == "d":
            val = clip_norm(raw, layout.distance_clip) / layout.distance_clip * v
        elif name == "theta":
            val = raw / np.pi * v
        elif name == "theta_dot":
            val = np.clip(raw / layout.velocity_scale, -1.0, 1.0) * v
        elif name == "contact":
            val = (raw * valid)[..., None]
        elif name == "force":
            val = (np.clip(raw / layout.force_scale, 0.0, 5.0) * valid)[..., None]
        else:
            val = (raw if raw.ndim == 3 else raw[..., None]) * v
        x[..., col] = val
    fc, tc = layout.node_col("finger"), layout.node_col("node_type")
    x[..., fc] = static[..., :6]
    x[..., tc] = static[..., 6:]
    return x


def static_features(finger: np.ndarray, node_type: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(B,N,12) float32: finger-class and node-type one-hots, zero on padded nodes."""
    x = np.concatenate([finger, node_type], axis=-1).astype(np.float64) * valid[..., None]
    return x.astype(np.float32)


_GLOBAL_SCALE = {"target": None, "v_wrist": 1.0, "w_wrist": 5.0, "v_obj": 1.0, "w_obj": 5.0}


def global_features(layout: ObservationLayout, **blocks: np.ndarray) -> np.ndarray:
    """(B, global_dim) float32 from the raw global blocks by name: ``target`` (B,3) m, ``v_wrist`` /
    ``v_obj`` (B,3) m/s, ``w_wrist`` / ``w_obj`` (B,3) rad/s, ``lift`` (B,) bool; any other block of the
    layout already normalized, (B,) or (B,w). Everything is clipped to [-1, 1]."""
    b = next(iter(blocks.values())).shape[0]
    g = np.empty((b, layout.global_dim))
    for name, width in layout.global_:
        raw = np.asarray(blocks[name], dtype=np.float64)
        if name == "target":
            val = raw / layout.target_scale
        elif name in _GLOBAL_SCALE:
            val = raw / _GLOBAL_SCALE[name]
        else:
            val = raw.reshape(b, width)
        g[:, layout.global_col(name)] = val.reshape(b, width)
    return np.clip(g, -1.0, 1.0).astype(np.float32)


def rotation_delta(r_prev: np.ndarray, r_now: np.ndarray) -> np.ndarray:
    """(B,3) world rotation vectors of r_now · r_prevᵀ (small angles)."""
    d = np.einsum("bij,bkj->bik", r_now, r_prev)
    return 0.5 * np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], axis=-1)
