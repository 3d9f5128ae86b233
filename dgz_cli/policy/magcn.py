"""MAGCN: Morphology-Aligned Graph Convolutional Network actor-critic (paper Sec. III-C-3, Supp. S3).

    E_p   = φ_p(X_phys)                      Linear(27→32) · LeakyReLU · Linear(32→d_p)       (B, N, d_p)
    H^(0) = X_node                                                                              (B, N, node_dim)
    H^(l) = ReLU(LayerNorm(Â [H^(l-1) ‖ E_p] W^(l))),  l = 1..L                                (B, N, w_l)
    E_g   = φ_g(x_g)                         Linear(global_dim→256) · LeakyReLU                 (B, 256)
    wrist = φ_dec,wrist([E_g ‖ e_wrist])     Linear(·→128) · LeakyReLU · Linear(128→6)          (B, 6)
    α_i   = φ_dec,node([E_node[i] ‖ M[i]])   Linear(·→128) · LeakyReLU · Linear(128→3)          (B, N, 3)
    V     = φ_v([E_g ‖ mean_valid E_node])   Linear(·→128) · ReLU · Linear(128→1)               (B,)

Ablations: ``use_physical=False`` drops E_p, ``early_fusion`` concatenates E_p at layer 1 only,
``use_mask=False`` feeds zeros for M. Padded nodes have zero rows/columns in Â and zeroed embeddings, so
they never influence valid outputs; their action dims are zero in the mean and excluded from log-probs.
The Gaussian policy has a learned state-independent log-std: 6 wrist values + 3 per-primitive values
shared by all nodes. Feature and action sizes, and the column that marks wrist nodes, come from the control
contract the network is built for (``MAGCN(cfg, contract)``).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from dgz_cli.policy.graph import action_valid, masked_mean, normalized_adjacency
from dgz_cli.policy.presets import MagcnConfig
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.models import NODE_TYPES

Obs = dict[str, torch.Tensor]


def _mlp(i: int, h: int, o: int, act: type[nn.Module], out_gain: float) -> nn.Sequential:
    net = nn.Sequential(nn.Linear(i, h), act(), nn.Linear(h, o))
    nn.init.orthogonal_(net[2].weight, gain=out_gain)
    nn.init.zeros_(net[2].bias)
    return net


class GraphTrunk(nn.Module):
    """φ_p, GCN layers and φ_g of a MAGCN-shaped encoder (the separate critic's; the actor keeps its own
    attributes so that checkpoints keep their parameter names)."""

    def __init__(self, node_dim: int, global_dim: int, widths: tuple[int, ...], cfg: MagcnConfig) -> None:
        super().__init__()
        p = cfg.phys_out if cfg.use_physical else 0
        self.phys = (nn.Sequential(nn.Linear(cfg.phys_dim, cfg.phys_hidden), nn.LeakyReLU(),
                                   nn.Linear(cfg.phys_hidden, cfg.phys_out)) if cfg.use_physical else None)
        self.fuse = [cfg.use_physical and (l == 0 or not cfg.early_fusion) for l in range(len(widths))]
        self.gcn = nn.ModuleList(nn.Linear(i + (p if f else 0), o, bias=False)
                                 for i, o, f in zip([node_dim, *widths[:-1]], widths, self.fuse))
        self.norms = nn.ModuleList(nn.LayerNorm(o) for o in widths)
        self.glob = nn.Sequential(nn.Linear(global_dim, widths[-1]), nn.LeakyReLU())

    def forward(self, obs: Obs) -> tuple[torch.Tensor, torch.Tensor]:
        """(E_g (B, w_L), E_node (B, N, w_L)), padded node rows zero."""
        return _encode(obs, self.phys, self.gcn, self.norms, self.fuse, self.glob)


def _encode(obs: Obs, phys, gcn, norms, fuse, glob) -> tuple[torch.Tensor, torch.Tensor]:
    valid = obs["node_valid"]
    vf = valid.to(obs["nodes"].dtype)[..., None]
    ahat = normalized_adjacency(obs["adjacency"], valid)
    ep = phys(obs["physical"]) if phys is not None else None
    h = obs["nodes"]
    for lin, norm, f in zip(gcn, norms, fuse):
        z = torch.cat([h, ep], dim=-1) if f else h
        # Padded rows become ReLU(LN(0)) here but Â has zero columns for them, so they never mix into
        # valid rows; they are zeroed once at the end (cheaper than masking every layer).
        h = torch.relu_(norm(torch.bmm(ahat, lin(z))))
    return glob(obs["global"]), h * vf


class MAGCN(nn.Module):
    def __init__(self, cfg: MagcnConfig = MagcnConfig(), contract: ControlContract = ControlContract()) -> None:
        super().__init__()
        self.cfg, self.contract = cfg, contract
        lay, act = contract.observation, contract.action
        self.node_dim, self.global_dim = lay.node_dim, lay.global_dim
        self.wrist_dim, self.n_prim = act.wrist_dim, act.n_prim
        self.wrist_col = lay.node_col("node_type").start + NODE_TYPES.index("wrist")
        p = cfg.phys_out if cfg.use_physical else 0
        self.phys = (nn.Sequential(nn.Linear(cfg.phys_dim, cfg.phys_hidden), nn.LeakyReLU(),
                                   nn.Linear(cfg.phys_hidden, cfg.phys_out)) if cfg.use_physical else None)
        ins = [self.node_dim, *cfg.gcn_widths[:-1]]
        self.fuse = [cfg.use_physical and (l == 0 or not cfg.early_fusion) for l in range(cfg.num_layers)]
        # W^(l) has no bias: the LayerNorm's shift plays that role (a bias inside Â(·) would be degree-scaled).
        self.gcn = nn.ModuleList(nn.Linear(i + (p if f else 0), o, bias=False)
                                 for i, o, f in zip(ins, cfg.gcn_widths, self.fuse))
        self.norms = nn.ModuleList(nn.LayerNorm(o) for o in cfg.gcn_widths)
        self.glob = nn.Sequential(nn.Linear(self.global_dim, cfg.global_hidden), nn.LeakyReLU())
        d = cfg.gcn_widths[-1]
        self.wrist_head = _mlp(cfg.global_hidden + d, cfg.head_hidden, self.wrist_dim, nn.LeakyReLU, 0.01)
        self.node_head = _mlp(d + self.n_prim, cfg.head_hidden, self.n_prim, nn.LeakyReLU, 0.01)
        if cfg.critic_widths is None:
            self.value_head = _mlp(cfg.global_hidden + d, cfg.value_hidden, 1, nn.ReLU, 1.0)
        else:
            self.critic = GraphTrunk(self.node_dim, self.global_dim, cfg.critic_widths, cfg)
            self.value_head = _mlp(2 * cfg.critic_widths[-1], cfg.value_hidden, 1, nn.ReLU, 1.0)
        self.log_std_wrist = nn.Parameter(torch.full((self.wrist_dim,), cfg.init_log_std))
        prim_shape = (len(NODE_TYPES), self.n_prim) if cfg.log_std_per_type else (self.n_prim,)
        self.log_std_prim = nn.Parameter(torch.full(prim_shape, cfg.init_log_std))
        self.type_cols = lay.node_col("node_type")
        self.mask_actions = act.mask_actions
        self.wrist_is_action = act.wrist_is_action

    # ------------------------------------------------------------------ encoder
    def encode(self, obs: Obs) -> tuple[torch.Tensor, torch.Tensor]:
        """Return (E_g (B, global_hidden), E_node (B, N, w_L)); padded node rows are zero."""
        return _encode(obs, self.phys, self.gcn, self.norms, self.fuse, self.glob)

    def wrist_embedding(self, obs: Obs, h: torch.Tensor) -> torch.Tensor:
        """(B, w_L): mean embedding of the wrist-type node(s); masked mean of all nodes if a graph has none."""
        w = obs["nodes"][..., self.wrist_col] * obs["node_valid"].to(h.dtype)  # (B, N)
        cnt = w.sum(-1, keepdim=True)
        e = torch.bmm((w / torch.where(cnt > 0, cnt, torch.ones_like(cnt))).unsqueeze(1), h).squeeze(1)
        return torch.where(cnt > 0, e, masked_mean(h, obs["node_valid"]))

    # ------------------------------------------------------------------ heads
    def forward(self, obs: Obs) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """obs (see :mod:`dgz_cli.policy.graph`) → mean (B, 6+3N), log_std (B, 6+3N), value (B,).

        Mean and log_std are zero on padded nodes' action dims.
        """
        eg, h = self.encode(obs)
        b, n, _ = h.shape
        valid = obs["node_valid"]
        m = obs["mask"] if self.cfg.use_mask else torch.zeros_like(obs["mask"])
        wrist = self.wrist_head(torch.cat([eg, self.wrist_embedding(obs, h)], dim=-1))
        alpha = self.node_head(torch.cat([h, m], dim=-1)) * valid.to(h.dtype)[..., None]
        mean = torch.cat([wrist, alpha.reshape(b, n * self.n_prim)], dim=-1)
        av = self.action_valid(obs).to(h.dtype)
        mean = mean * av
        if self.cfg.log_std_per_type:
            prim = (obs["nodes"][..., self.type_cols] @ self.log_std_prim).reshape(b, n * self.n_prim)
        else:
            prim = self.log_std_prim.repeat(n).expand(b, -1)
        log_std = torch.cat([self.log_std_wrist.expand(b, -1), prim], dim=-1) * av
        if self.cfg.critic_widths is not None:
            eg, h = self.critic(obs)
        value = self.value_head(torch.cat([eg, masked_mean(h, valid)], dim=-1)).squeeze(-1)
        return mean, log_std, value

    def action_valid(self, obs: Obs) -> torch.Tensor:
        """(B, action_dim) bool: the wrist dims and the dims of real (not padded) nodes; with the contract's
        ``mask_actions``, only the primitives the activation mask enables, and the wrist only if it is an
        action (``ActionLayout.wrist_is_action``)."""
        av = action_valid(obs["node_valid"], self.wrist_dim, self.n_prim)
        if self.mask_actions:
            av = av.clone()
            av[:, self.wrist_dim:] &= (obs["mask"] > 0).reshape(av.shape[0], -1)
        if not self.wrist_is_action:
            av[:, :self.wrist_dim] = False
        return av

    def critic_parameters(self) -> list[nn.Parameter]:
        """The parameters only the value depends on: the value head, and the critic's own trunk if separate."""
        critic = list(self.critic.parameters()) if self.cfg.critic_widths is not None else []
        return list(self.value_head.parameters()) + critic

    @torch.no_grad()
    def clamp_log_std(self, minimum: float | None = None, maximum: float | None = None) -> None:
        """Exploration bounds: no log-std parameter below ``minimum`` or above ``maximum`` (None: unbounded)."""
        self.log_std_wrist.clamp_(min=minimum, max=maximum)
        self.log_std_prim.clamp_(min=minimum, max=maximum)

    @torch.no_grad()
    def act(self, obs: Obs) -> torch.Tensor:
        """The deterministic action: the Gaussian's mean (B, action_dim), zero on padded dims."""
        return self(obs)[0]

    @torch.no_grad()
    def sample(self, obs: Obs) -> dict[str, torch.Tensor]:
        """A sampled action for a rollout: ``action`` (B, A) (unbounded Gaussian sample, zero on padded dims;
        the environment clips it), ``log_prob`` (B,), ``value`` (B,), ``mean`` (B, A), ``log_std`` (B, A)."""
        mean, log_std, value = self(obs)
        av = self.action_valid(obs)
        action = (mean + log_std.exp() * torch.randn_like(mean)) * av
        return dict(action=action, log_prob=gaussian_log_prob(mean, log_std, action, av), value=value, mean=mean,
                    log_std=log_std)

    def evaluate(self, obs: Obs, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """log_prob (B,), entropy (B,), value (B,) of ``action`` (B, 6+3N), summed over valid action dims."""
        mean, log_std, value = self(obs)
        av = self.action_valid(obs)
        return gaussian_log_prob(mean, log_std, action, av), gaussian_entropy(log_std, av), value


# ---------------------------------------------------------------------- Gaussian helpers
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def gaussian_log_prob(mean: torch.Tensor, log_std: torch.Tensor, action: torch.Tensor, av: torch.Tensor) -> torch.Tensor:
    """Σ over valid dims (``av`` (B, D) bool) of the diagonal-Gaussian log-density → (B,)."""
    z = (action - mean) * torch.exp(-log_std)
    lp = -0.5 * z * z - log_std - _HALF_LOG_2PI
    return (lp * av.to(lp.dtype)).sum(-1)


def gaussian_entropy(log_std: torch.Tensor, av: torch.Tensor) -> torch.Tensor:
    """Σ over valid dims of the per-dim entropy 0.5 + ½log 2π + log σ → (B,)."""
    return ((0.5 + _HALF_LOG_2PI + log_std) * av.to(log_std.dtype)).sum(-1)


def gaussian_kl(mean0: torch.Tensor, log_std0: torch.Tensor, mean1: torch.Tensor, log_std1: torch.Tensor,
                av: torch.Tensor) -> torch.Tensor:
    """KL(N0 ‖ N1) summed over valid dims → (B,)."""
    var0, var1 = torch.exp(2 * log_std0), torch.exp(2 * log_std1)
    kl = log_std1 - log_std0 + (var0 + (mean0 - mean1) ** 2) / (2 * var1) - 0.5
    return (kl * av.to(kl.dtype)).sum(-1)


# ---------------------------------------------------------------------- cost accounting
def parameter_count(cfg: MagcnConfig, contract: ControlContract = ControlContract()) -> int:
    return sum(p.numel() for p in MAGCN(cfg, contract).parameters())


def flops_per_graph(cfg: MagcnConfig, n_nodes: int = 20, contract: ControlContract = ControlContract()) -> int:
    """Analytic forward FLOPs (2 × multiply-adds) for one graph of ``n_nodes`` nodes.

    Counts every Linear (weights only) and the dense Â·(ZW) products (N² per output channel per layer),
    i.e. exactly the matmuls :meth:`MAGCN.forward` runs; biases, LayerNorm, activations and pooling
    (O(N·width) element-wise work) are left out.
    """
    n, p = n_nodes, (cfg.phys_out if cfg.use_physical else 0)
    node_dim, global_dim = contract.observation.node_dim, contract.observation.global_dim
    wrist_dim, n_prim = contract.action.wrist_dim, contract.action.n_prim

    def trunk(widths: tuple[int, ...], global_out: int) -> int:
        macs = n * (cfg.phys_dim * cfg.phys_hidden + cfg.phys_hidden * cfg.phys_out) if cfg.use_physical else 0
        for l, (i, o) in enumerate(zip([node_dim, *widths[:-1]], widths)):
            fuse = cfg.use_physical and (l == 0 or not cfg.early_fusion)
            macs += n * (i + (p if fuse else 0)) * o + n * n * o
        return macs + global_dim * global_out

    macs = trunk(cfg.gcn_widths, cfg.global_hidden)
    d = cfg.gcn_widths[-1]
    macs += (cfg.global_hidden + d) * cfg.head_hidden + cfg.head_hidden * wrist_dim
    macs += n * ((d + n_prim) * cfg.head_hidden + cfg.head_hidden * n_prim)
    if cfg.critic_widths is None:
        macs += (cfg.global_hidden + d) * cfg.value_hidden + cfg.value_hidden
    else:
        macs += trunk(cfg.critic_widths, cfg.critic_widths[-1])
        macs += 2 * cfg.critic_widths[-1] * cfg.value_hidden + cfg.value_hidden
    return 2 * macs
