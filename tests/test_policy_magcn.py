"""MAGCN: normalized adjacency by hand, padding invariance, mask conditioning, ablations, FLOPs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from dgz_cli.policy.graph import normalized_adjacency, to_tensors
from dgz_cli.policy.magcn import MAGCN, flops_per_graph, parameter_count
from dgz_cli.policy.presets import PRESETS, MagcnConfig, get_preset
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.models import NODE_TYPES

COL_WRIST = ControlContract().observation.node_col("node_type").start + NODE_TYPES.index("wrist")

SMALL = MagcnConfig(gcn_widths=(16, 24, 24), global_hidden=32, head_hidden=16, value_hidden=16, phys_out=8)
# wrist → 2 fingers of 3 nodes, and a thumb of 2
PARENTS = [-1, 0, 1, 2, 0, 4, 5, 0, 7]


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def graph(parents=PARENTS, n_pad: int | None = None, seed: int = 0) -> dict[str, np.ndarray]:
    """One hand graph (batch 1), padded to ``n_pad`` nodes with garbage-free zeros."""
    rng = np.random.default_rng(seed)
    n = len(parents)
    N = n_pad or n
    obs = dict(nodes=np.zeros((1, N, 23), np.float32), adjacency=np.zeros((1, N, N), np.float32),
               physical=np.zeros((1, N, 27), np.float32), mask=np.zeros((1, N, 3), np.float32),
               node_valid=np.zeros((1, N), bool))
    obs["global"] = rng.uniform(-1, 1, (1, 16)).astype(np.float32)
    obs["nodes"][0, :n, :17] = rng.uniform(-1, 1, (n, 17))
    obs["nodes"][0, 0, COL_WRIST] = 1.0
    obs["nodes"][0, np.arange(1, n), 18 + np.arange(1, n) % 5] = 1.0
    obs["physical"][0, :n] = rng.uniform(-1, 1, (n, 27))
    obs["mask"][0, :n] = rng.random((n, 3)) < 0.6
    obs["node_valid"][0, :n] = True
    for j, p in enumerate(parents):
        if p >= 0:
            obs["adjacency"][0, p, j] = 1.0
    return obs


def cat(*obs):
    return {k: np.concatenate([o[k] for o in obs]) for k in obs[0]}


def model(cfg=SMALL, seed=0):
    torch.manual_seed(seed)
    return MAGCN(cfg)


def test_normalized_adjacency_by_hand_chain_with_padding():
    adj = torch.tensor([[[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0], [0, 0, 0, 0]]], dtype=torch.float32)
    adj[0, 2, 3] = 1.0  # an edge into the padded node must be dropped
    valid = torch.tensor([[True, True, True, False]])
    a = normalized_adjacency(adj, valid)[0]
    # Ã = [[1,1,0],[1,1,1],[0,1,1]], degrees 2, 3, 2
    s6 = 1 / math.sqrt(6)
    expect = torch.tensor([[0.5, s6, 0, 0], [s6, 1 / 3, s6, 0], [0, s6, 0.5, 0], [0, 0, 0, 0]])
    torch.testing.assert_close(a, expect)
    assert torch.equal(a[3], torch.zeros(4)) and torch.equal(a[:, 3], torch.zeros(4))
    assert torch.equal(a, a.T)


def test_to_tensors_dtypes_and_unbatched():
    o = graph()
    t = to_tensors({k: v[0] for k, v in o.items()})
    assert t["nodes"].shape == (1, 9, 23) and t["node_valid"].dtype == torch.bool and t["global"].dtype == torch.float32
    with pytest.raises(KeyError):
        to_tensors({"nodes": o["nodes"]})


def test_forward_shapes_and_padded_action_dims_are_zero():
    m = model()
    obs = to_tensors(graph(n_pad=12))
    mean, log_std, value = m(obs)
    assert mean.shape == log_std.shape == (1, 6 + 36) and value.shape == (1,)
    assert torch.equal(mean[0, 6 + 27:], torch.zeros(9))
    out = m.sample(obs)
    assert torch.equal(out["action"][0, 6 + 27:], torch.zeros(9)) and out["log_prob"].shape == (1,)
    assert not torch.equal(out["action"], mean)
    torch.testing.assert_close(m.act(obs), mean)


@pytest.mark.parametrize("cfg", [SMALL, SMALL.model_copy(update=dict(early_fusion=True)),
                                 SMALL.model_copy(update=dict(use_physical=False))], ids=["full", "early", "nophys"])
def test_padding_invariance(cfg):
    m = model(cfg)
    other = graph([-1, 0, 1, 0], seed=3)
    a = to_tensors(cat(graph(n_pad=9), graph([-1, 0, 1, 0], n_pad=9, seed=3)))
    b = to_tensors(cat(graph(n_pad=15), graph([-1, 0, 1, 0], n_pad=15, seed=3)))
    ma, sa, va = m(a)
    mb, sb, vb = m(b)
    torch.testing.assert_close(va, vb, atol=1e-5, rtol=0)
    torch.testing.assert_close(ma, mb[:, :ma.shape[1]], atol=1e-5, rtol=0)
    torch.testing.assert_close(sa, sb[:, :sa.shape[1]])
    assert torch.equal(mb[:, ma.shape[1]:], torch.zeros_like(mb[:, ma.shape[1]:]))
    # the 4-node graph alone, unpadded, gives the same outputs as inside a padded batch
    m1, _, v1 = m(to_tensors(other))
    torch.testing.assert_close(v1, va[1:], atol=1e-5, rtol=0)
    torch.testing.assert_close(m1, ma[1:, :6 + 12], atol=1e-5, rtol=0)
    act = torch.randn_like(mb)
    lp_a, ent_a, _ = m.evaluate(a, act[:, :ma.shape[1]])
    lp_b, ent_b, _ = m.evaluate(b, act)
    torch.testing.assert_close(lp_a, lp_b, atol=1e-4, rtol=0)
    torch.testing.assert_close(ent_a, ent_b)


def test_padded_nodes_do_not_affect_valid_outputs():
    m = model()
    clean = graph(n_pad=13)
    dirty = {k: v.copy() for k, v in clean.items()}
    rng = np.random.default_rng(7)
    for k in ("nodes", "physical", "mask"):
        dirty[k][0, 9:] = rng.uniform(-3, 3, dirty[k][0, 9:].shape)
    dirty["adjacency"][0, 2, 10] = dirty["adjacency"][0, 11, 4] = dirty["adjacency"][0, 9, 12] = 1.0
    (m0, _, v0), (m1, _, v1) = m(to_tensors(clean)), m(to_tensors(dirty))
    torch.testing.assert_close(m0, m1, atol=0, rtol=0)
    torch.testing.assert_close(v0, v1, atol=0, rtol=0)


def test_mask_conditions_the_node_head_only_when_enabled():
    base = graph()
    flipped = {k: v.copy() for k, v in base.items()}
    flipped["mask"][0, 3] = 1.0 - flipped["mask"][0, 3]
    for use_mask in (True, False):
        m = model(SMALL.model_copy(update=dict(use_mask=use_mask)))
        (m0, _, v0), (m1, _, v1) = m(to_tensors(base)), m(to_tensors(flipped))
        node3 = slice(6 + 9, 6 + 12)
        assert (not torch.equal(m0[:, node3], m1[:, node3])) == use_mask
        others = torch.ones(m0.shape[1], dtype=torch.bool)
        others[node3] = False
        assert torch.equal(m0[:, others], m1[:, others])  # the mask feeds only its own node's head
        assert torch.equal(v0, v1)


def test_wrist_embedding_uses_the_wrist_node_or_falls_back_to_the_mean():
    m = model()
    obs = to_tensors(cat(graph(), graph()))
    obs["nodes"][1, :, COL_WRIST] = 0.0  # second graph has no wrist-type node
    _, h = m.encode(obs)
    e = m.wrist_embedding(obs, h)
    torch.testing.assert_close(e[0], h[0, 0])
    torch.testing.assert_close(e[1], h[1].mean(0))


def test_ablation_flags_change_parameter_shapes():
    d, p = ControlContract().observation.node_dim, SMALL.phys_out
    full = model(SMALL)
    assert [l.in_features for l in full.gcn] == [d + p, 16 + p, 24 + p]
    early = model(SMALL.model_copy(update=dict(early_fusion=True)))
    assert [l.in_features for l in early.gcn] == [d + p, 16, 24]
    nophys = model(SMALL.model_copy(update=dict(use_physical=False)))
    assert [l.in_features for l in nophys.gcn] == [d, 16, 24] and nophys.phys is None
    nomask = model(SMALL.model_copy(update=dict(use_mask=False)))
    assert [s.shape for s in nomask.state_dict().values()] == [s.shape for s in full.state_dict().values()]
    assert full.node_head[0].in_features == 24 + 3 and full.wrist_head[0].in_features == 32 + 24
    assert full.log_std_wrist.shape == (6,) and full.log_std_prim.shape == (3,)


def test_log_prob_and_entropy_sum_over_valid_dims_only():
    m = model()
    obs = to_tensors(graph(n_pad=11))
    mean, log_std, _ = m(obs)
    act = torch.randn_like(mean)
    lp, ent, _ = m.evaluate(obs, act)
    k = 6 + 3 * 9
    dist = torch.distributions.Normal(mean[:, :k], log_std[:, :k].exp())
    torch.testing.assert_close(lp, dist.log_prob(act[:, :k]).sum(-1))
    torch.testing.assert_close(ent, dist.entropy().sum(-1))


def test_backward_reaches_every_parameter():
    m = model()
    obs = to_tensors(cat(graph(n_pad=10), graph([-1, 0, 1], n_pad=10, seed=1)))
    lp, ent, v = m.evaluate(obs, torch.randn(2, 36))
    (lp.sum() + v.sum()).backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in m.parameters())


def test_gradients_match_finite_differences():
    m = model().double()
    obs = {k: (v.double() if v.is_floating_point() else v) for k, v in to_tensors(graph(n_pad=11)).items()}

    def f(nodes, phys):
        mean, log_std, value = m({**obs, "nodes": nodes, "physical": phys})
        return mean.sum() + value.sum()

    args = (obs["nodes"].clone().requires_grad_(True), obs["physical"].clone().requires_grad_(True))
    assert torch.autograd.gradcheck(f, args, eps=1e-6, atol=1e-6)


def test_flops_per_graph_paper_matches_hand_count():
    cfg = PRESETS["paper"]
    n = 20
    phys = n * (27 * 32 + 32 * 32)
    gcn = n * ((23 + 32) * 128 + (128 + 32) * 256 + 8 * (256 + 32) * 256) + n * n * (128 + 9 * 256)
    heads = 16 * 256 + (256 + 256) * 128 + 128 * 6 + n * ((256 + 3) * 128 + 128 * 3) + (256 + 256) * 128 + 128
    assert flops_per_graph(cfg, n) == 2 * (phys + gcn + heads) == 29_147_648
    assert abs(flops_per_graph(cfg, n) - 29e6) / 29e6 < 0.15
    assert cfg.num_layers == 10 and cfg.gcn_widths == (128,) + (256,) * 9


def test_compact_preset_is_much_cheaper_and_deep_enough():
    paper, compact = get_preset("paper"), get_preset("compact")
    assert compact.num_layers >= 4
    assert flops_per_graph(paper) / flops_per_graph(compact) >= 5
    assert parameter_count(paper) == 814_899
    with pytest.raises(KeyError):
        get_preset("huge")
    with pytest.raises(Exception):
        MagcnConfig(gcn_widths=())


def test_separate_critic_owns_the_value_and_never_moves_the_actor():
    """critic_widths (issue 11, lever 7): the value comes from the critic's own trunk; a value loss reaches only
    critic parameters and a policy loss only actor parameters; the actor's outputs equal the shared-trunk
    model's with the same actor weights."""
    cfg = SMALL.model_copy(update=dict(critic_widths=(8, 8)))
    m = model(cfg)
    shared = model(SMALL)
    shared.load_state_dict({k: v for k, v in m.state_dict().items() if not k.startswith(("critic.", "value_head."))},
                           strict=False)
    obs = to_tensors(cat(graph(n_pad=10), graph([-1, 0, 1], n_pad=10, seed=1)))
    mean, log_std, value = m(obs)
    torch.testing.assert_close(mean, shared(obs)[0])
    critic = {n for n, _ in m.named_parameters() if n.startswith(("critic.", "value_head."))}
    assert any(n.startswith("critic.gcn.") for n in critic)
    value.sum().backward()
    for n, p in m.named_parameters():
        assert (p.grad is not None and p.grad.abs().sum() > 0) == (n in critic), n
    m.zero_grad(set_to_none=True)
    m.evaluate(obs, torch.randn(2, 36))[0].sum().backward()
    assert all(p.grad is None or not p.grad.any() for n, p in m.named_parameters() if n in critic)
    # analytic FLOPs: the shared value head is replaced by the critic trunk + its head
    n = 20
    lay = ControlContract().observation
    trunk = (n * (27 * 32 + 32 * 8) + n * (lay.node_dim + 8) * 8 + n * n * 8 + n * (8 + 8) * 8 + n * n * 8
             + lay.global_dim * 8)
    assert flops_per_graph(cfg, n) - flops_per_graph(SMALL, n) == 2 * (trunk + 16 * 16 - (32 + 24) * 16)
