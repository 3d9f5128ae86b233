"""Observation dict → tensors, and the GCN normalized adjacency (dense, batched; hand graphs have ~20 nodes).

The observation's keys, shapes and column layout are the control contract's
(:mod:`dgz_cli.spec.contract`).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import torch

OBS_KEYS = ("nodes", "global", "adjacency", "physical", "mask", "node_valid")
_RANK = {"nodes": 3, "global": 2, "adjacency": 3, "physical": 3, "mask": 3, "node_valid": 2}


def to_tensors(obs: Mapping[str, np.ndarray | torch.Tensor], device: str | torch.device = "cpu") -> dict[str, torch.Tensor]:
    """Convert an observation dict (numpy or torch) to float32 tensors on ``device`` (``node_valid`` → bool).

    Unknown keys are dropped. An unbatched observation (``nodes`` of shape (N, node_dim)) gets a batch axis of 1.
    """
    missing = [k for k in OBS_KEYS if k not in obs]
    if missing:
        raise KeyError(f"observation lacks {missing}; expected keys {OBS_KEYS}")
    unbatched = np.ndim(obs["nodes"]) == 2
    out: dict[str, torch.Tensor] = {}
    for k in OBS_KEYS:
        v = obs[k]
        t = v.to(device) if isinstance(v, torch.Tensor) else torch.as_tensor(np.asarray(v), device=device)
        t = t.bool() if k == "node_valid" else t.float()
        if unbatched:
            t = t.unsqueeze(0)
        if t.dim() != _RANK[k]:
            raise ValueError(f"obs[{k!r}] has shape {tuple(t.shape)}; expected rank {_RANK[k]} (batched)")
        out[k] = t
    return out


def normalized_adjacency(adj: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Â = D̃^-1/2 Ã D̃^-1/2 with Ã = sym(A) + I on valid nodes; (B, N, N) → (B, N, N).

    ``sym(A)`` is the binary symmetrization of the parent→child adjacency (any diagonal of ``adj`` is
    ignored); self-loops are added on valid nodes only, and edges touching padded nodes are dropped, so
    rows and columns of padded nodes are exactly zero.
    """
    v = valid.to(adj.dtype)
    n = adj.shape[-1]
    eye = torch.eye(n, dtype=adj.dtype, device=adj.device)
    a = ((adj + adj.transpose(-1, -2)) > 0).to(adj.dtype) * (1.0 - eye)
    a = a * v[..., :, None] * v[..., None, :] + eye * v[..., :, None]
    deg = a.sum(-1)
    dinv = torch.where(deg > 0, deg.clamp_min(1e-12).rsqrt(), torch.zeros_like(deg))
    return dinv[..., :, None] * a * dinv[..., None, :]


def action_valid(valid: torch.Tensor, wrist_dim: int = 6, n_prim: int = 3) -> torch.Tensor:
    """(B, wrist_dim + n_prim·N) bool: wrist dims always valid, then n_prim dims per valid node (node-major)."""
    b = valid.shape[0]
    wrist = torch.ones(b, wrist_dim, dtype=torch.bool, device=valid.device)
    return torch.cat([wrist, valid.bool().repeat_interleave(n_prim, dim=1)], dim=1)


def masked_mean(h: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean of node rows (B, N, D) over valid nodes → (B, D); zeros for a graph with no valid node."""
    w = valid.to(h.dtype)[..., None]
    return (h * w).sum(1) / w.sum(1).clamp_min(1.0)
