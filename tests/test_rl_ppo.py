"""PPO pieces: GAE by hand, adaptive-KL schedule by hand, mini-batches, and a toy update that learns."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dgz_cli.policy.graph import to_tensors
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.policy.presets import MagcnConfig
from dgz_cli.rl.config import PPOConfig
from dgz_cli.rl.ppo import PPO
from dgz_cli.rl.schedule import AdaptiveKLSchedule
from dgz_cli.rl.storage import RolloutStorage

TINY = MagcnConfig(gcn_widths=(16, 16), global_hidden=16, head_hidden=16, value_hidden=16, phys_out=8)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def toy_obs(B: int, N: int = 4, seed: int = 0) -> dict[str, np.ndarray]:
    """B copies of a wrist + 3-node chain (last env padded to 3 nodes) with random node/global features."""
    rng = np.random.default_rng(seed)
    adj = np.zeros((B, N, N), np.float32)
    adj[:, 0, 1] = adj[:, 1, 2] = adj[:, 2, 3] = 1.0
    valid = np.ones((B, N), bool)
    valid[-1, -1] = False
    adj[-1, 2, 3] = 0.0
    nodes = rng.uniform(-1, 1, (B, N, 23)).astype(np.float32)
    nodes[..., 17:] = 0.0
    nodes[:, 0, 17] = 1.0
    nodes *= valid[..., None]
    return {"nodes": nodes, "global": rng.uniform(-1, 1, (B, 16)).astype(np.float32), "adjacency": adj,
            "physical": (rng.uniform(-1, 1, (1, N, 27)) * valid[..., None]).astype(np.float32),
            "mask": np.ones((B, N, 3), np.float32) * valid[..., None], "node_valid": valid}


def filled_storage(rewards, values, terminated, truncated, final_value=None, T=3, B=2):
    st = RolloutStorage(T, B)
    obs = toy_obs(B)
    for t in range(T):
        st.add(obs, np.zeros((B, 18)), np.zeros(B), values[t], rewards[t], terminated[t], truncated[t],
               final_value=None if final_value is None else final_value[t])
    return st


def test_gae_and_returns_by_hand():
    """γ = λ = 0.5. env 0: terminated at t = 1; env 1: truncated at t = 0 with V(final obs) = 3.

    env 0  t=2: δ = 3 + .5·2 (V(s_T)) − 1.5 = 2.5            A = 2.5
           t=1: δ = 2 + 0 (terminated) − 1 = 1               A = 1        (trace cut)
           t=0: δ = 1 + .5·1 − .5 = 1                         A = 1 + .25·1 = 1.25
    env 1  t=2: δ = 1 + .5·8 − 4 = 1                          A = 1
           t=1: δ = 1 + .5·4 − 2 = 1                          A = 1 + .25·1 = 1.25
           t=0: δ = 1 + .5·3 (bootstrap, final obs) − 1 = 1.5  A = 1.5      (trace cut)
    """
    rewards = [[1, 1], [2, 1], [3, 1]]
    values = [[0.5, 1], [1, 2], [1.5, 4]]
    term = [[False, False], [True, False], [False, False]]
    trunc = [[False, True], [False, False], [False, False]]
    final = [[0, 3.0], [0, 0], [0, 0]]
    st = filled_storage(rewards, values, term, trunc, final)
    st.compute_returns(torch.tensor([2.0, 8.0]), gamma=0.5, lam=0.5)
    adv = torch.tensor([[1.25, 1.5], [1.0, 1.25], [2.5, 1.0]])
    torch.testing.assert_close(st.advantages, adv)
    torch.testing.assert_close(st.returns, adv + torch.tensor(values))

    # without the final observation's value, the step's own value bootstraps: δ = 1 + .5·1 − 1 = .5
    st = filled_storage(rewards, values, term, trunc)
    st.compute_returns(torch.tensor([2.0, 8.0]), gamma=0.5, lam=0.5)
    assert st.advantages[0, 1].item() == pytest.approx(0.5)
    # terminated wins over truncated: no bootstrap
    st = filled_storage(rewards, values, term, [[False, True], [True, False], [False, False]], final)
    st.compute_returns(torch.tensor([2.0, 8.0]), gamma=0.5, lam=0.5)
    assert st.advantages[1, 0].item() == pytest.approx(1.0)


def test_adaptive_kl_schedule_by_hand():
    s = AdaptiveKLSchedule(lr=1e-3, desired_kl=0.01)
    seq = [s.step(kl) for kl in (0.03, 0.001, 0.01, 0.02, 0.005, 0.0, 0.0021)]
    expect = [1e-3 / 1.5, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1.5e-3]  # thresholds and kl = 0 leave lr unchanged
    assert seq == pytest.approx(expect, rel=1e-12)
    lo = AdaptiveKLSchedule(lr=1.2e-5)
    assert lo.step(1.0) == 1e-5 and lo.step(1.0) == 1e-5
    hi = AdaptiveKLSchedule(lr=9e-3)
    assert hi.step(1e-4) == 1e-2 and hi.step(1e-4) == 1e-2


def test_mini_batches_cover_every_transition_once_and_gather_static_obs():
    T, B = 4, 6
    st = RolloutStorage(T, B, seed=3)
    obs = toy_obs(B)
    obs["physical"] = np.broadcast_to(np.arange(B, dtype=np.float32)[:, None, None], (B, 4, 27)).copy()
    for t in range(T):
        obs["global"] = np.full((B, 16), t, np.float32)
        st.add(obs, np.full((B, 18), t), np.zeros(B), np.zeros(B), np.arange(B) + 10 * t, np.zeros(B, bool),
               np.zeros(B, bool))
    st.compute_returns(torch.zeros(B), 0.9, 0.9)
    assert "physical" in st.static_keys and st.obs["physical"].shape == (B, 4, 27)
    seen = []
    for mb in st.mini_batches(3):
        t, b = mb.obs["global"][:, 0], mb.obs["physical"][:, 0, 0]
        assert torch.equal(mb.actions[:, 0], t) and mb.returns.shape == (8,)
        seen += (t * B + b).long().tolist()
    assert sorted(seen) == list(range(T * B))

    def order(seed):
        st.generator = torch.Generator().manual_seed(seed)
        return [mb.actions[:, 0].tolist() for mb in st.mini_batches(2)]

    assert order(5) == order(5) != order(6)
    st.clear()
    st.add(obs, np.zeros((B, 18)), np.zeros(B), np.zeros(B), np.zeros(B), np.zeros(B, bool), np.zeros(B, bool))
    obs["physical"][0] += 1.0
    with pytest.raises(ValueError, match="static"):
        st.add(obs, np.zeros((B, 18)), np.zeros(B), np.zeros(B), np.zeros(B), np.zeros(B, bool), np.zeros(B, bool))


def test_ppo_config_and_keywords_agree_and_conflict():
    m = MAGCN(TINY)
    assert PPO(m, PPOConfig(gamma=0.9)).cfg.gamma == 0.9
    assert PPO(m, gamma=0.9).cfg == PPOConfig(gamma=0.9)
    assert PPO(m).cfg == PPOConfig() and PPOConfig().learning_rate == 5e-4 and PPOConfig().num_epochs == 4
    with pytest.raises(ValueError):
        PPO(m, PPOConfig(), gamma=0.9)


def _bandit_round(ppo: PPO, obs_t, T=4, B=32, store_dist=True):
    """One-step episodes, reward = first wrist action: advantageous actions have a[:, 0] > 0."""
    st = RolloutStorage(T, B, seed=0)
    for _ in range(T):
        out = ppo.act(obs_t)
        if not store_dist:
            out.pop("mean"), out.pop("log_std")
        st.add(obs_t, reward=out["action"][:, 0], terminated=torch.ones(B, dtype=torch.bool),
               truncated=torch.zeros(B, dtype=torch.bool), **out)
    return st


def test_ppo_update_increases_log_prob_of_advantageous_actions():
    torch.manual_seed(0)
    m = MAGCN(TINY)
    ppo = PPO(m, learning_rate=3e-3, schedule="fixed")
    obs_t = to_tensors(toy_obs(32))
    st = _bandit_round(ppo, obs_t)
    ppo.compute_returns(st, obs_t)
    actions, adv = st.actions.reshape(-1, 18).clone(), st.advantages.flatten().clone()
    big_obs = {k: (v.repeat(4, *[1] * (v.dim() - 1))) for k, v in obs_t.items()}
    with torch.no_grad():
        lp0 = m.evaluate(big_obs, actions)[0]
    stats = ppo.update(st)
    with torch.no_grad():
        lp1 = m.evaluate(big_obs, actions)[0]
    gain = lp1 - lp0
    assert gain[adv > 0].mean() > 0 > gain[adv < 0].mean()
    assert st.step == 0 and stats["num_updates"] == 16
    assert {"loss", "surrogate_loss", "value_loss", "entropy", "kl", "clip_fraction", "learning_rate"} <= set(stats)
    # repeated rounds move the mean of the rewarded dim up
    mean0 = m(obs_t)[0][:, 0].mean().item()
    for _ in range(6):
        st = _bandit_round(ppo, obs_t)
        ppo.update(st, ppo.value(obs_t))
    assert m(obs_t)[0][:, 0].mean().item() > mean0 + 0.1


def test_adaptive_lr_and_optimizer_state_round_trip():
    torch.manual_seed(1)
    m = MAGCN(TINY)
    ppo = PPO(m, learning_rate=1e-3)
    obs_t = to_tensors(toy_obs(32))
    stats = ppo.update(_bandit_round(ppo, obs_t, store_dist=False), ppo.value(obs_t))  # k3 KL estimate path
    assert np.isfinite(stats["kl"]) and stats["learning_rate"] != 1e-3
    tensors = ppo.optimizer_tensors()
    assert all(isinstance(v, torch.Tensor) for v in tensors.values()) and any(k.endswith("exp_avg") for k in tensors)
    other = PPO(MAGCN(TINY))
    other.load_optimizer_tensors(tensors, stats["learning_rate"])
    assert other.learning_rate == stats["learning_rate"] == other.schedule.lr
    for k, v in other.optimizer_tensors().items():
        torch.testing.assert_close(v, tensors[k])


def test_prioritised_mini_batches_follow_the_env_weights():
    """Lever 8: with env priorities the mini-batches draw T·B transitions with replacement, env b's ∝ weight b;
    a zero weight is never drawn, bad weights are refused, and None restores the one shuffled pass."""
    T, B = 5, 4
    st = RolloutStorage(T, B, seed=1)
    obs = toy_obs(B)
    obs["physical"] = np.broadcast_to(np.arange(B, dtype=np.float32)[:, None, None], (B, 4, 27)).copy()  # env id
    for t in range(T):
        obs["global"] = np.full((B, 16), t, np.float32)
        st.add(obs, np.zeros((B, 18)), np.zeros(B), np.zeros(B), np.zeros(B), np.zeros(B, bool), np.zeros(B, bool))
    st.compute_returns(torch.zeros(B), 0.9, 0.9)
    st.set_env_priority(np.array([3.0, 1.0, 0.0, 0.0]))
    envs = [int(e) for _ in range(300) for mb in st.mini_batches(2) for e in mb.obs["physical"][:, 0, 0]]
    assert len(envs) == 300 * T * B
    counts = np.bincount(envs, minlength=B)
    assert counts[2] == counts[3] == 0 and abs(counts[0] / counts[1] - 3.0) < 0.25
    for bad in (np.zeros(B), np.array([1.0, -1.0, 1.0, 1.0]), np.array([1.0, np.nan, 1.0, 1.0]), np.ones(3)):
        with pytest.raises(ValueError, match="priorities"):
            st.set_env_priority(bad)
    st.set_env_priority(None)
    seen = [int(t * B + b) for mb in st.mini_batches(2)
            for t, b in zip(mb.obs["global"][:, 0], mb.obs["physical"][:, 0, 0])]
    assert sorted(seen) == list(range(T * B))


def test_env_priority_from_pair_success_emas_by_hand():
    from types import SimpleNamespace

    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.rl.runner import PAIR_EMA, Trainer

    me = SimpleNamespace(pair_success={}, cfg=TrainConfig(failure_priority=0.1),
                         env=SimpleNamespace(pair_names=["a/x", "a/y", "b/x", "a/x"]))
    ep = lambda h, o, s: dict(hand=h, object=o, success=s)  # noqa: E731
    w = Trainer.env_priority(me, [ep("a", "x", True), ep("a", "y", False)])
    np.testing.assert_allclose(w, [0.1, 1.1, 1.1, 0.1])  # first outcomes set the EMAs; b/x unseen: 1 − 0 + 0.1
    w = Trainer.env_priority(me, [ep("a", "x", False)])
    np.testing.assert_allclose(w[0], 1 - (1 - PAIR_EMA) + 0.1)
    assert me.pair_success == {"a/x": pytest.approx(1 - PAIR_EMA), "a/y": 0.0}


@pytest.mark.parametrize("critic", [None, (8, 8)])
def test_a_critic_only_update_fits_the_value_and_leaves_the_actor(critic):
    """``critic_only`` steps move only the value head (and a separate critic's trunk): every other parameter,
    hence the actor's mean and std, is bit-identical, the value loss falls and the adaptive learning rate is not
    stepped; a normal update afterwards moves the actor again."""
    torch.manual_seed(0)
    m = MAGCN(TINY.model_copy(update=dict(critic_widths=critic)))
    ppo = PPO(m, learning_rate=3e-3)
    obs_t = to_tensors(toy_obs(32))
    critic_ids = {id(p) for p in m.critic_parameters()}
    assert critic_ids and len(critic_ids) < len(list(m.parameters()))
    actor0 = {n: p.detach().clone() for n, p in m.named_parameters() if id(p) not in critic_ids}
    value0 = {n: p.detach().clone() for n, p in m.named_parameters() if id(p) in critic_ids}
    st = _bandit_round(ppo, obs_t)
    ppo.compute_returns(st, obs_t)
    returns = st.returns.clone()  # (T, B)
    mse = lambda: float(((ppo.value(obs_t)[None] - returns) ** 2).mean())
    before = mse()
    stats = ppo.update(st, critic_only=True)
    assert mse() < before and stats["learning_rate"] == 3e-3
    for n, p in m.named_parameters():
        if id(p) in critic_ids:
            assert not torch.equal(p, value0[n]), n
        else:
            assert torch.equal(p, actor0[n]), n
    ppo.update(_bandit_round(ppo, obs_t), ppo.value(obs_t))
    assert not torch.equal(m.log_std_wrist, actor0["log_std_wrist"])
