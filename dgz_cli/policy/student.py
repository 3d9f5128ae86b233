"""The distilled student (issue 12; paper Sec. III-D, Supp. "Privileged Distillation Details"): the teacher's
MAGCN without the privileged inputs, plus a single-layer LSTM (hidden 256) over the last K = 5 steps.

Per step, a parameter-free *token* summarises what hardware gives (the student's observation layout has no
``contact``/``force``):

    token_t = [ x_g (G) ‖ for each finger class c: mean over the hand's class-c nodes of the dynamic node
                blocks (d, θ, θ̇, and pd_error if the layout has it; F columns) (6·F) ‖ class present (6) ‖ 1 ]

(the last column marks a real step; the history of a fresh episode is zero-padded, so 0 marks padding). The
finger classes are the morphology-aligned semantics MAGCN already uses, so the token has the same meaning
on every hand. The history H (B, K, token_dim), oldest first, goes through the LSTM from a zero state; its
last output m (B, 256) enters the MAGCN as a residual on the embeddings:

    E_g'       = E_g + P_g m                       P_g: Linear(256 → global_hidden), zero-initialised
    E_node'[i] = (E_node[i] + P_n m) · valid_i     P_n: Linear(256 → w_L), zero-initialised

and the heads are the teacher's. Initialisation from the teacher (:func:`init_from_teacher`): every tensor
whose name and shape match is copied; the first GCN layer, whose input lost the privileged columns, gets the
teacher's columns of the remaining blocks. With P_g = P_n = 0 the student starts as the teacher fed no
contact or force — the BC/DAgger then teaches the memory to stand in for them.

The observation dict of :mod:`dgz_cli.policy.graph` gets one more key, ``history`` (B, K, token_dim) float32;
:class:`TokenHistory` keeps it for a batch of episodes (``push`` each step, ``reset`` rows at episode start).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from dgz_cli.policy.magcn import MAGCN, Obs
from dgz_cli.policy.presets import MagcnConfig
from dgz_cli.policy.student_config import StudentConfig
from dgz_cli.spec.contract import ControlContract, ObservationLayout
from dgz_cli.spec.models import FINGER_CLASSES

STATIC_BLOCKS = ("finger", "node_type")


def dynamic_blocks(layout: ObservationLayout) -> tuple[str, ...]:
    """The node blocks a token pools (all but the static one-hots)."""
    return tuple(n for n, _ in layout.node if n not in STATIC_BLOCKS)


def token_dim(layout: ObservationLayout) -> int:
    f = sum(w for n, w in layout.node if n not in STATIC_BLOCKS)
    k = len(FINGER_CLASSES)
    return layout.global_dim + k * f + k + 1


def tokens(nodes: np.ndarray, glob: np.ndarray, node_valid: np.ndarray, layout: ObservationLayout) -> np.ndarray:
    """(B, token_dim) float32 tokens of one step: nodes (B, N, node_dim), glob (B, global_dim), node_valid (B, N)."""
    nodes = np.asarray(nodes, dtype=np.float64)
    dyn = np.concatenate([nodes[..., layout.node_col(n)] for n in dynamic_blocks(layout)], axis=-1)  # (B, N, F)
    cls = nodes[..., layout.node_col("finger")] * np.asarray(node_valid, dtype=np.float64)[..., None]  # (B, N, 6)
    count = cls.sum(1)  # (B, 6)
    pooled = np.einsum("bnc,bnf->bcf", cls, dyn) / np.maximum(count, 1.0)[..., None]
    b = nodes.shape[0]
    out = np.concatenate([np.asarray(glob, dtype=np.float64), pooled.reshape(b, -1), (count > 0).astype(np.float64),
                          np.ones((b, 1))], axis=1)
    return out.astype(np.float32)


class TokenHistory:
    """The last K tokens of B episodes, (B, K, token_dim) oldest first; zero rows are padding."""

    def __init__(self, batch: int, history: int, dim: int) -> None:
        self.buf = np.zeros((batch, history, dim), np.float32)

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Forget the episodes where ``mask`` (B,) is True (all when None): their next step starts a history."""
        if mask is None:
            self.buf[:] = 0.0
        else:
            self.buf[np.asarray(mask, dtype=bool)] = 0.0

    def push(self, token: np.ndarray) -> np.ndarray:
        """Append one step's tokens (B, token_dim); returns the history (B, K, token_dim) (a view: copy to keep)."""
        self.buf[:, :-1] = self.buf[:, 1:]
        self.buf[:, -1] = token
        return self.buf

    def steps(self) -> np.ndarray:
        """(B,) how many real steps each history holds (≤ K)."""
        return self.buf[..., -1].sum(-1).round().astype(np.int64)


class StudentMAGCN(MAGCN):
    """MAGCN + LSTM memory (module docstring). ``forward``/``sample``/``evaluate``/``act`` are MAGCN's, on
    observations that also carry ``history`` (B, K, token_dim)."""

    def __init__(self, cfg: MagcnConfig, contract: ControlContract, student: StudentConfig = StudentConfig()) -> None:
        if contract.privileged_inputs:
            raise ValueError(f"a student observes no privileged inputs; the layout has {contract.privileged_inputs}")
        super().__init__(cfg, contract)
        self.student = student
        self.token_dim = token_dim(contract.observation)
        self.lstm = nn.LSTM(self.token_dim, student.lstm_hidden, num_layers=1, batch_first=True)
        self.mem_global = nn.Linear(student.lstm_hidden, cfg.global_hidden)
        self.mem_node = nn.Linear(student.lstm_hidden, cfg.gcn_widths[-1])
        for lin in (self.mem_global, self.mem_node):
            nn.init.zeros_(lin.weight)
            nn.init.zeros_(lin.bias)

    def memory(self, history: torch.Tensor) -> torch.Tensor:
        """(B, K, token_dim) → the LSTM's last output (B, lstm_hidden), from a zero state."""
        out, _ = self.lstm(history)
        return out[:, -1]

    def encode(self, obs: Obs) -> tuple[torch.Tensor, torch.Tensor]:
        """MAGCN's (E_g (B, global_hidden), E_node (B, N, w_L)) plus the memory's residuals."""
        eg, h = super().encode(obs)
        m = self.memory(obs["history"])
        vf = obs["node_valid"].to(h.dtype)[..., None]
        return eg + self.mem_global(m), (h + self.mem_node(m)[:, None, :]) * vf


def init_from_teacher(student: StudentMAGCN, teacher_state: dict[str, torch.Tensor],
                      teacher_layout: ObservationLayout) -> dict[str, int]:
    """Copy the teacher's weights (``state_dict`` names) into the student wherever name and shape match; the
    first GCN layer's input columns are matched by observation block. Returns counts of copied / partly
    copied / fresh tensors."""
    own = student.state_dict()
    lay = student.contract.observation
    copied = partial = 0
    with torch.no_grad():
        for name, t in own.items():
            src = teacher_state.get(name)
            if src is None:
                continue
            if src.shape == t.shape:
                t.copy_(src)
                copied += 1
            elif name == "gcn.0.weight" and src.shape[0] == t.shape[0]:
                # input columns: [node blocks ‖ E_p]; copy block by block, then the physical embedding's
                for block, _ in lay.node:
                    t[:, lay.node_col(block)] = src[:, teacher_layout.node_col(block)]
                extra = t.shape[1] - lay.node_dim
                if extra:
                    t[:, lay.node_dim:] = src[:, teacher_layout.node_dim:teacher_layout.node_dim + extra]
                partial += 1
    student.load_state_dict(own)
    return dict(copied=copied, partial=partial, fresh=len(own) - copied - partial)


def student_obs(obs_t: dict[str, torch.Tensor], history: np.ndarray) -> dict[str, torch.Tensor]:
    """The observation tensors plus ``history`` (B, K, token_dim) as a float32 tensor (copied)."""
    return {**obs_t, "history": torch.as_tensor(np.array(history, dtype=np.float32, copy=True))}
