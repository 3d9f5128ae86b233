"""Issue 11's levers, each through the control contract or the env config: wrist guidance, the narrow-width
start roll, the GraspXL-code reward, Markov finger state (PD error, lead cap), masked action dims, the
exploration floor and per-type log-std. Hand-computed where possible."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from dgz_cli.policy.graph import to_tensors
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.policy.presets import MagcnConfig
from dgz_cli.rl.config import PPOConfig
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.reward import graspxl_terms, graspxl_total
from dgz_cli.sim.slot import pick_roll
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ActionLayout, ClosingPrior,
                                   ControlContract, ObservationLayout, WristGuidance, finger_targets)
from dgz_cli.spec.envconfig import EnvConfig, GraspXLReward
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec
from conftest import needs_assets

TRI = load_spec(resolve_spec("dgz_tri"))
MARKOV = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)
TINY = MagcnConfig(gcn_widths=(16, 16), global_hidden=16, head_hidden=16, value_hidden=16, phys_out=8)


def test_guidance_by_hand():
    g = WristGuidance(gain=0.1, speed_cap=0.01)
    d = g.delta(np.array([[0.05, 0.0, 0.10], [0.0, 0.0, 0.30]]), np.array([[0.0, 0.0, 0.05]] * 2),
                np.array([True, True]))
    np.testing.assert_allclose(d[0], [0.005, 0, 0.005, 0, 0, 0])          # 0.1 × (0.05, 0, 0.05): under the cap
    np.testing.assert_allclose(d[1], [0, 0, 0.01, 0, 0, 0])               # 0.1 × 0.25 = 0.025 → capped at 0.01
    assert not g.delta(np.ones((1, 3)), np.zeros((1, 3)), np.array([False])).any()  # only in the grasp phase


def test_guidance_stop_gap_by_hand():
    g = WristGuidance(gain=0.1, speed_cap=0.01, stop_gap=0.05)
    target, grasp = np.array([[0.05, 0.0, 0.10]] * 3), np.zeros((3, 3))
    d = g.delta(target, grasp, np.array([True] * 3), palm_gap=np.array([0.08, 0.04, 0.04]))
    np.testing.assert_allclose(d[0, :3], np.array([0.005, 0, 0.01]) * 0.01 / math.hypot(0.005, 0.01))  # far: capped
    np.testing.assert_allclose(d[1, :3], [0.005, 0, 0])  # near: no push along n, still centred along f
    back = g.delta(np.array([[0.0, 0.0, -0.02]]), np.zeros((1, 3)), np.array([True]), palm_gap=np.array([0.01]))
    np.testing.assert_allclose(back[0, :3], [0, 0, -0.002])  # a grasp point past the target may still back off
    with pytest.raises(ValueError, match="palm gap"):
        g.delta(target, grasp, np.array([True] * 3))


def test_guidance_stop_gap_reads_the_wrist_node_and_the_clip():
    c = ControlContract(guidance=WristGuidance(gain=0.1, stop_gap=0.05))
    lay = c.observation
    nodes = np.zeros((2, 3, lay.node_dim))
    from dgz_cli.spec.models import NODE_TYPES
    nodes[:, 0, lay.node_col("node_type").start + NODE_TYPES.index("wrist")] = 1.0
    nodes[0, 0, lay.node_col("d")] = np.array([0.0, 0.03, 0.04]) / lay.distance_clip  # palm 5 cm from the surface
    nodes[1, 0, lay.node_col("d")] = np.array([0.0, 0.0, 0.04]) / lay.distance_clip
    nodes[:, 1, lay.node_col("d")] = 0.0  # a finger touching does not count: only the wrist node
    valid = np.ones((2, 3), bool)
    np.testing.assert_allclose(c.palm_gap(nodes, valid), [0.05, 0.04])
    glob = np.zeros((2, lay.global_dim))
    glob[:, lay.global_col("target")] = np.array([0.0, 0.0, 0.06]) / lay.target_scale
    g = c.guidance_action(glob, np.zeros((2, 3)), np.array([True, True]), nodes, valid)
    np.testing.assert_allclose(g[:, 2], [0.006, 0.0])  # 5 cm is not below the 5 cm gap; 4 cm is
    with pytest.raises(ValueError, match="nodes and node_valid"):
        c.guidance_action(glob, np.zeros((2, 3)), np.array([True, True]))
    with pytest.raises(ValueError, match="below the observation's distance_clip"):
        ControlContract(guidance=WristGuidance(gain=0.1, stop_gap=0.3))


def test_aim_residual_shifts_the_guidances_aim_by_hand():
    """``guidance.aim_residual``: the wrist's translation action no longer moves the palm by ``wrist_scale``; it
    shifts the guidance's aim by ``aim_residual`` per unit, so the step is gain × (target + shift − grasp point),
    capped like any guidance step; rotation dims keep ``wrist_scale``; outside the grasp phase translation does
    nothing. It needs the guidance on."""
    c = ControlContract(guidance=WristGuidance(gain=0.1, speed_cap=0.01, aim_residual=0.05))
    lay = c.observation
    glob = np.zeros((3, lay.global_dim))
    glob[:, lay.global_col("target")] = np.array([0.0, 0.0, 0.06]) / lay.target_scale
    wrist = np.array([[0.0, 0.4, 0.0, 0.5, 0.0, 0.0], [1.0, 1.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.4, 0.0, 0.5, 0.0, 0.0]])
    cmd = c.wrist_command(wrist, glob, np.zeros((3, 3)), np.array([True, True, False]))
    # aim shifted 0.4 × 5 cm = 2 cm along l: 0.1 × (0, 0.02, 0.06); rotation 0.5 × 1 cm
    np.testing.assert_allclose(cmd[0], [0.0, 0.002, 0.006, 0.005, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cmd[1, :3], np.array([0.05, 0.05, 0.11]) * 0.01 / np.linalg.norm([0.05, 0.05, 0.11]))
    np.testing.assert_allclose(cmd[2], [0, 0, 0, 0.005, 0, 0], atol=1e-12)  # lift / hold: no translation at all
    velocity = ControlContract(guidance=WristGuidance(gain=0.1, speed_cap=0.01))
    np.testing.assert_allclose(velocity.wrist_command(wrist[:1], glob[:1], np.zeros((1, 3)), np.array([True]))[0],
                               [0.0, 0.004, 0.006, 0.005, 0, 0], atol=1e-12)  # by default 0.4 × 1 cm per step
    with pytest.raises(ValueError, match="needs guidance.gain > 0"):
        ControlContract(guidance=WristGuidance(aim_residual=0.05))
    lateral = ControlContract(guidance=WristGuidance(gain=0.1, speed_cap=0.01, aim_residual=0.05,
                                                     aim_axes=(False, True, False)))
    mixed = np.array([[0.2, 0.4, 0.3, 0.0, 0.0, 0.0]])
    # l shifts the aim (0.1 × 0.02 = 0.002); f and n stay velocities (0.2 and 0.3 × 1 cm) on the guidance's (0, _, 0.006)
    np.testing.assert_allclose(lateral.wrist_command(mixed, glob[:1], np.zeros((1, 3)), np.array([True]))[0],
                               [0.002, 0.002, 0.009, 0, 0, 0], atol=1e-12)


def test_an_aim_residual_holds_the_palm_off_a_moving_aim_instead_of_driving_it_on():
    """In the env, a constant lateral translation action under ``aim_residual`` settles the palm at a fixed
    offset from the guided position (gain 0.05: about aim × action after a few time constants); the same action
    as a velocity keeps moving the palm until the guidance's pull balances it, and on a target that moves with
    the palm (a pushed object) it would never stop."""
    moved = {}
    for aim in (0.02, None):
        c = ControlContract(observation=MARKOV, guidance=WristGuidance(gain=0.05, aim_residual=aim))
        env = _env(EnvConfig(contract=c))
        env.reset()
        a = np.zeros((1, env.action_dim))
        a[:, 1] = 1.0
        rot0 = env.state()["palm_rot"][0].copy()
        guided = _env(EnvConfig(contract=c))
        guided.reset()
        for _ in range(80):
            env.step(a)
            guided.step(np.zeros((1, env.action_dim)))
        moved[aim] = float((rot0.T @ (env.state()["palm_pos"][0] - guided.state()["palm_pos"][0]))[1])
        env.close()
        guided.close()
    assert 0.012 < moved[0.02] < 0.021  # the aim shift (2 cm) less what the guidance has not yet closed
    assert moved[None] > 0.1  # 1 cm per step against the guidance's pull: settles at 0.01 / 0.05 = 20 cm


def test_finger_lead_cap_by_hand():
    act = ActionLayout(finger_max_lead=0.05)
    one = lambda *v: np.array([v], dtype=float)  # noqa: E731
    idx = np.zeros((1, 1), dtype=int)  # one joint: node 0, FLEX, slot 0
    args = (idx, idx, one(1.0), idx, one(-3.0), one(3.0), act)
    # target 0.04 ahead of q already, +1 action (0.015): capped at q + 0.05
    assert finger_targets(one(0.04), np.ones((1, 1, 3)), *args, q=one(0.0))[0, 0] == pytest.approx(0.05)
    # a joint pushed back 0.2 rad: the lead is not yanked back, but does not grow either
    assert finger_targets(one(0.2), np.ones((1, 1, 3)), *args, q=one(0.0))[0, 0] == pytest.approx(0.2)
    # without the cap the target just integrates
    assert finger_targets(one(0.2), np.ones((1, 1, 3)), *args[:-1], ActionLayout(), q=one(0.0))[0, 0] == pytest.approx(0.215)


def test_graspxl_terms_by_hand():
    d = np.array([[[0.1, 0, 0], [0.2, 0, 0], [0, 0, 0]]])       # 3 nodes, the third padding
    w = np.array([[1.0, 4.0, 0.0]])                              # node 1 a fingertip
    t = graspxl_terms(d, np.array([[True, False, True]]), np.array([[0.5, 3.0, 9.0]]), w,
                      np.array([[0.0, 0.3, 0.4]]), np.array([0.25]), np.array([True]), np.array([False]),
                      np.array([True]), 0.5)
    assert t["dis"][0] == pytest.approx(-(0.1 + 4 * 0.2) / 5)
    assert t["contact"][0] == pytest.approx(1 / 5) and t["force"][0] == pytest.approx((0.5 + 4 * 1.0) / 5)
    assert t["objvel"][0] == pytest.approx(-0.25) and t["lift"][0] == pytest.approx(0.5)
    assert t["success"][0] == 0 and t["push"][0] == -1
    w8 = GraspXLReward()
    assert graspxl_total(t, w8)[0] == pytest.approx(0.3 * t["dis"][0] + 0.2 + 0.5 * 0.9 - 1.5 * 0.25 + 3 * 0.5 - 10)
    assert t["residual"][0] == 0  # no residual given
    t2 = graspxl_terms(d, np.array([[True, False, True]]), np.array([[0.5, 3.0, 9.0]]), w,
                       np.array([[0.0, 0.3, 0.4]]), np.array([0.25]), np.array([True]), np.array([False]),
                       np.array([True]), 0.5, residual_sq=np.array([0.16]))
    assert graspxl_total(t2, GraspXLReward(residual=2.0))[0] == pytest.approx(graspxl_total(t, w8)[0] - 0.32)
    assert t["displace"][0] == 0  # no displacement given


def test_displacement_term_counts_the_grasp_phase_only_and_saturates_at_the_push_limit():
    d, w = np.zeros((3, 1, 3)), np.ones((3, 1))
    no = np.zeros(3, bool)
    t = graspxl_terms(d, np.zeros((3, 1), bool), np.zeros((3, 1)), w, np.zeros((3, 3)), np.zeros(3),
                      np.array([False, False, True]), no, no, 0.5,
                      displacement=np.array([0.06, 0.9, 0.06]), push_limit=0.3)
    assert t["displace"] == pytest.approx([-0.2, -1.0, 0.0])  # 6 cm of 30; capped; lifting: not counted
    base = graspxl_total(t, GraspXLReward())
    assert graspxl_total(t, GraspXLReward(displace=2.0)) == pytest.approx(base + 2.0 * t["displace"])


def test_residual_term_counts_only_active_dims():
    """r_residual = −mean a² over the wrist and the mask-enabled primitives; an inactive primitive's action
    (and the prior's own action) costs nothing."""
    cfg = EnvConfig(contract=ControlContract(observation=MARKOV, prior=ClosingPrior(enabled=True, close_step=0)),
                    reward_variant="graspxl", graspxl=GraspXLReward(residual=1.0))
    env = _env(cfg)
    env.reset()
    n_active = int(env._active_dims.sum())
    assert n_active == 6 + int(((env.mask > 0) & env.node_valid[..., None]).sum())
    inactive = np.nonzero(env._active_dims[0] == 0)[0]
    assert len(inactive)  # dgz_tri has inactive primitives
    a = np.zeros((1, env.action_dim))
    a[0, inactive] = 1.0
    _, _, _, _, info = env.step(a)
    assert info["reward_terms"]["residual"][0] == 0  # the prior closes (step ≥ 0) and inactive dims are free
    a[0, :6] = 0.5
    _, _, _, _, info = env.step(a)
    assert info["reward_terms"]["residual"][0] == pytest.approx(-6 * 0.25 / n_active)
    env.close()


def _env(cfg: EnvConfig, obj: str = "box") -> GraspEnv:
    return GraspEnv([(TRI, resolve_objects(obj)[0])], cfg, seed=4, threads=1)


def test_guidance_moves_the_wrist_without_any_action():
    still = _env(EnvConfig())
    guided = _env(EnvConfig(contract=ControlContract(guidance=WristGuidance(gain=0.05))))
    gaps = []
    for env in (still, guided):
        obs = env.reset()
        start = np.linalg.norm(obs["global"][0, :3])
        for _ in range(30):
            obs, *_ = env.step(np.zeros((1, env.action_dim)))
        gaps.append(start - np.linalg.norm(obs["global"][0, :3]))
        env.close()
    assert abs(gaps[0]) < 0.03 and gaps[1] > 0.2  # normalized by 0.5 m: the guided palm came > 10 cm closer


def test_markov_layout_observes_pd_error_guide_and_phase():
    cfg = EnvConfig(contract=ControlContract(observation=MARKOV, guidance=WristGuidance(gain=0.05)))
    env = _env(cfg)
    obs = env.reset()
    lay = cfg.contract.observation
    assert obs["nodes"].shape[-1] == 26 and obs["global"].shape[-1] == 20
    assert obs["global"][0, lay.global_col("phase")] == 0.0
    a = np.zeros((1, env.action_dim))
    a[0, 6::3] = 1.0  # +FLEX everywhere: the targets lead the joints
    obs, *_ = env.step(a)
    assert obs["global"][0, lay.global_col("phase")] == pytest.approx(1 / 190)
    pd = obs["nodes"][0, :, lay.node_col("pd_error")]
    assert pd[:, 0].max() > 0.01  # FLEX leads
    guide = obs["global"][0, lay.global_col("guide")] * lay.target_scale
    target = obs["global"][0, lay.global_col("target")] * lay.target_scale
    np.testing.assert_allclose(guide, target - env.grasp_offset[0], atol=1e-6)
    env.close()


def test_narrow_roll_closes_across_the_narrow_side():
    """A box's narrow side lies along the hand's closing axis at reset, far more often than by chance."""
    cfg = EnvConfig(roll="narrow")
    env = GraspEnv([(TRI, resolve_objects("box")[0])] * 6, cfg, seed=1, threads=1)
    env.reset()
    widths = {"narrow": [], "uniform": []}
    for name, e in (("narrow", env), ("uniform", GraspEnv([(TRI, resolve_objects("box")[0])] * 6, EnvConfig(),
                                                           seed=1, threads=1))):
        e.reset()
        state = e.state()
        for b, s in enumerate(e.slots):
            axis = state["palm_rot"][b] @ s.idx.closing_axis
            pts = s.idx.cloud @ state["obj_rot"][b].T
            widths[name].append(np.ptp(pts @ axis))
        e.close()
    assert np.mean(widths["narrow"]) < 0.8 * np.mean(widths["uniform"])


def test_push_ends_the_episode_as_a_true_terminal_state():
    cfg = EnvConfig(reward_variant="graspxl", graspxl=GraspXLReward(push_limit=0.01))
    env = _env(cfg, "sphere")
    env.reset()
    s = env.slots[0]
    s.data.qvel[s.idx.object_dadr] = 2.0  # shove the ball: it leaves the 1 cm limit within a step
    obs, reward, terminated, truncated, info = env.step(np.zeros((1, env.action_dim)))
    assert terminated[0] and not truncated[0] and info["episode"][0]["pushed"]
    assert reward[0] < -9 and "r_objvel" in info["episode"][0]
    env.close()


def test_masked_actions_are_neither_sampled_nor_scored():
    contract = ControlContract(action=ActionLayout(mask_actions=True))
    env = _env(EnvConfig(contract=contract))
    obs = to_tensors(env.reset())
    env.close()
    torch.manual_seed(0)
    m = MAGCN(TINY, contract)
    out = m.sample(obs)
    inactive = (obs["mask"] == 0).reshape(1, -1)
    assert inactive.any()
    assert torch.all(out["action"][:, 6:][inactive] == 0) and torch.all(out["mean"][:, 6:][inactive] == 0)
    full = MAGCN(TINY)
    full.load_state_dict(m.state_dict())
    lp_full = full.evaluate(obs, out["action"])[0]
    lp_masked = m.evaluate(obs, out["action"])[0]
    per_dim = -0.5 * math.log(2 * math.pi) - TINY.init_log_std  # log-density of a 0 action at mean 0
    assert (lp_full - lp_masked).item() == pytest.approx(per_dim * int(inactive.sum()), rel=1e-4)


def test_per_type_log_std_and_the_floor():
    from dgz_cli.rl.ppo import PPO

    env = _env(EnvConfig())
    obs = to_tensors(env.reset())
    env.close()
    m = MAGCN(TINY.model_copy(update=dict(log_std_per_type=True)))
    assert m.log_std_prim.shape == (6, 3)
    with torch.no_grad():
        m.log_std_prim[5] = -3.0  # node type 5 = fingertip (NODE_TYPES order)
    log_std = m(obs)[1][0, 6:].reshape(-1, 3)
    tip = obs["nodes"][0, :, m.type_cols][:, 5] > 0
    assert torch.all(log_std[tip] == -3.0) and torch.all(log_std[~tip & obs["node_valid"][0]] == TINY.init_log_std)
    ppo = PPO(m, PPOConfig(min_std=0.2))
    m.clamp_log_std(math.log(0.2))
    assert float(m.log_std_prim.detach().min()) == pytest.approx(math.log(0.2))
    assert ppo.cfg.min_std == 0.2


def test_closing_prior_by_hand_and_in_the_env():
    c = ControlContract(observation=MARKOV, prior=ClosingPrior(enabled=True, close_gap=0.03, close_step=50))
    lay = c.observation
    nodes = np.zeros((2, 3, lay.node_dim), np.float32)
    nodes[:, 0, lay.node_col("node_type").start + 0] = 1.0          # node 0: the wrist (NODE_TYPES[0])
    nodes[:, 0, lay.node_col("d")] = [0.0, 0.0, 0.02 / 0.3]          # palm 2 cm from the surface
    nodes[1, 0, lay.node_col("d")] = [0.0, 0.0, 0.2 / 0.3]           # slot 1: 20 cm
    glob = np.zeros((2, lay.global_dim), np.float32)
    glob[:, lay.global_col("phase")] = 10 / 190
    mask = np.array([[[1, 0, 0], [1, 0, 0], [0, 0, 0]]] * 2, np.float32)  # closing: FLEX of FLEX-active nodes
    a = c.prior_action(nodes, glob, mask, np.ones((2, 3), bool))
    np.testing.assert_array_equal(a[0, 6:], [0, 0, 0, 1, 0, 0, 0, 0, 0])  # only node 1: not the wrist, FLEX active
    assert not a[1].any() and not a[:, :6].any()
    glob[1, lay.global_col("phase")] = 50 / 190  # step 50: close regardless of the gap
    assert c.prior_action(nodes, glob, mask, np.ones((2, 3), bool))[1, 9] == 1
    with pytest.raises(ValueError, match="phase"):
        ControlContract(prior=ClosingPrior(enabled=True))  # the paper's layout has no phase block
    # close_guide: slot 1 (20 cm from the surface, step 10) closes once the guidance error is below 8 cm
    cg = ControlContract(observation=MARKOV, prior=ClosingPrior(enabled=True, close_guide=0.08))
    glob[1, lay.global_col("phase")] = 10 / 190
    glob[1, lay.global_col("guide")] = np.array([0.0, 0.06, 0.09]) / lay.target_scale  # ‖·‖ = 0.108 m
    assert not cg.prior_action(nodes, glob, mask, np.ones((2, 3), bool))[1].any()
    glob[1, lay.global_col("guide")] = np.array([0.0, 0.03, 0.07]) / lay.target_scale  # 0.076 m
    assert cg.prior_action(nodes, glob, mask, np.ones((2, 3), bool))[1, 9] == 1
    assert not c.prior_action(nodes, glob, mask, np.ones((2, 3), bool))[1].any()  # off without close_guide
    # in the env: zero policy actions + the prior close the hand from step 50 on
    env = _env(EnvConfig(contract=c))
    env.reset()
    for _ in range(60):
        obs, *_ = env.step(np.zeros((1, env.action_dim)))
    assert obs["nodes"][0, :, lay.node_col("theta")][:, 0].max() > 0.03  # > 0.09 rad of flexion (÷ π)
    env.close()


def test_joint_mode_mask_and_closing_follow_each_joint():
    """In the joint action mode (the w/o-primitives ablation) a node's 3 values drive its joints in M_h
    order: the mask marks the slots that drive a joint, and the prior closes each FLEX joint in its own
    direction (Barrett's FLEX joints close with sign −1; its spread joints are ABD and stay out)."""
    from dgz_cli.sim.scene import static_graph

    barrett = load_spec(resolve_spec("barrett"))
    ids = {n.id: i for i, n in enumerate(barrett.nodes)}
    g = static_graph(barrett, "joint")
    mid, thumb = ids["middle_proximal"], ids["thumb_proximal"]
    np.testing.assert_array_equal(g["mask"][mid], [1, 1, 0])       # prox (ABD), med (FLEX)
    np.testing.assert_array_equal(g["closing"][mid], [0, -1, 0])    # only the FLEX joint, its sign
    np.testing.assert_array_equal(g["closing"][thumb], [-1, 0, 0])  # finger 3's med joint is slot 0
    assert g["mask"].sum() == len(barrett.joints) and np.count_nonzero(g["closing"]) == sum(
        r.primitive.value == "FLEX" for r in barrett.joints)
    crowded = barrett.model_copy(update=dict(joints=[r.model_copy(update=dict(node="middle_proximal"))
                                                     for r in barrett.joints]))
    with pytest.raises(DgzError, match="drives 8 joints"):  # 3 values per node cannot drive 8 joints
        static_graph(crowded, "joint")
    p = static_graph(barrett)  # the primitive mode: the activation mask, +1 on FLEX of FLEX-active nodes
    np.testing.assert_array_equal(p["closing"][:, 0], p["mask"][:, 0] > 0)
    assert not p["closing"][:, 1:].any()


@needs_assets()
def test_the_closing_prior_closes_a_joint_mode_hand():
    """Zero policy actions + the prior from step 0 in the joint mode: every FLEX joint moves in its closing
    direction (sign · Δq > 0), the spread joints do not move."""
    barrett = load_spec(resolve_spec("barrett"))
    c = ControlContract(observation=MARKOV, prior=ClosingPrior(enabled=True, close_step=0),
                        action=ActionLayout(mode="joint"))
    env = GraspEnv([(barrett, resolve_objects("box")[0])], EnvConfig(contract=c), seed=4, threads=1)
    env.reset()
    t0 = env.targets.copy()
    for _ in range(10):
        env.step(np.zeros((1, env.action_dim)))
    moved = (env.targets - t0)[0, :env.L]
    flex = np.array([r.primitive.value == "FLEX" for r in barrett.joints])
    sign = np.array([r.sign for r in barrett.joints])
    assert (sign[flex] * moved[flex] > 0.1).all()   # 10 steps × 0.015 rad, unless a limit stops it
    np.testing.assert_array_equal(moved[~flex], 0.0)
    env.close()


def test_no_mask_ablation_turns_action_masking_off():
    from dgz_cli.rl.config import TrainConfig, env_config

    assert env_config(TrainConfig(mask_actions=True)).contract.action.mask_actions
    assert not env_config(TrainConfig(mask_actions=True, ablation="no_mask")).contract.action.mask_actions


def test_residual_gains_scale_the_policy_not_the_prior():
    c = ControlContract(observation=MARKOV, prior=ClosingPrior(enabled=True, close_step=0),
                        action=ActionLayout(mask_actions=True, wrist_residual=0.0, finger_residual=0.25))
    lay = c.observation
    nodes = np.zeros((1, 2, lay.node_dim), np.float32)
    nodes[:, 0, lay.node_col("node_type").start + 0] = 1.0  # node 0 is the wrist
    glob = np.zeros((1, lay.global_dim), np.float32)
    mask = np.array([[[1, 0, 0], [1, 0, 0]]], np.float32)  # closing: FLEX on both nodes
    policy = np.array([[0.5, -0.5, 1, 1, 1, 1] + [0.4, 0.8, 0] + [-0.4, 0.8, 0]])
    out = c.compose(policy, nodes, glob, mask, np.ones((1, 2), bool))
    # wrist × 0; fingers × 0.25; the prior's +1 FLEX on node 1 (not the wrist node) is not scaled
    np.testing.assert_allclose(out[0], [0] * 6 + [0.1, 0.2, 0] + [-0.1 + 1.0, 0.2, 0])
    same = ControlContract(observation=MARKOV)
    np.testing.assert_array_equal(same.compose(policy, nodes, glob, mask, np.ones((1, 2), bool)), policy)
    # with wrist_residual 0 the wrist dims are not actions: never sampled, and the env's wrist follows the
    # guidance alone (a wrist action of 1 moves nothing)
    env = _env(EnvConfig(contract=c.model_copy(update=dict(observation=MARKOV))))
    obs = to_tensors(env.reset())
    m = MAGCN(TINY, c)
    assert torch.all(m.sample(obs)["action"][:, :6] == 0)
    palm0 = env.state()["palm_pos"].copy()
    a = np.zeros((1, env.action_dim))
    a[:, :3] = 1.0
    env.step(a)
    assert np.linalg.norm(env.state()["palm_pos"] - palm0) < 1e-3  # 1 cm per step if the wrist action acted
    env.close()


def test_a_wrist_translation_factor_scales_translation_only_and_holds_the_palm():
    """``wrist_translation_residual`` scales the wrist's first three (translation) dims alone; the rotation dims
    keep ``wrist_residual``. At 0 a translation action of 1 does not move the palm, while the same action with
    the factor unset moves it 1 cm per step along the palm axes."""
    c = ControlContract(observation=MARKOV, action=ActionLayout(wrist_residual=0.25, wrist_translation_residual=0.0))
    assert c.action.translation_factors == (0.0, 0.0, 0.0) and c.action.scales_residual and c.action.wrist_is_action
    np.testing.assert_array_equal(c.action.residual_gains(2), [0, 0, 0, 0.25, 0.25, 0.25] + [1.0] * 6)
    assert ActionLayout(wrist_residual=0.25).translation_factors == (0.25, 0.25, 0.25)
    assert not ActionLayout(mask_actions=True, wrist_residual=0.0, wrist_translation_residual=0.0).wrist_is_action
    assert ActionLayout(mask_actions=True, wrist_residual=0.0, wrist_translation_residual=0.5).wrist_is_action
    moved = {}
    for factor in (0.0, None):
        action = ActionLayout(wrist_translation_residual=factor)
        env = _env(EnvConfig(contract=ControlContract(observation=MARKOV, action=action)))
        env.reset()
        palm0 = env.state()["palm_pos"].copy()
        a = np.zeros((1, env.action_dim))
        a[:, :3] = 1.0
        for _ in range(3):
            env.step(a)
        moved[factor] = float(np.linalg.norm(env.state()["palm_pos"] - palm0))
        env.close()
    assert moved[0.0] < 1e-3 < 0.01 < moved[None]


def test_a_per_axis_translation_factor_holds_the_palm_on_that_axis_alone():
    """``wrist_translation_residual`` (f, l, n) = (1, 0, 1): the same translation action of 1 on all three axes
    moves the palm about 1 cm per step along f and n and under 2 mm along l (palm frame at the start); the factors
    reach the action gains in that order, and a factor outside [0, 1] is refused."""
    action = ActionLayout(wrist_residual=0.25, wrist_translation_residual=(1.0, 0.0, 1.0))
    assert action.translation_factors == (1.0, 0.0, 1.0)
    np.testing.assert_array_equal(action.residual_gains(1), [1, 0, 1, 0.25, 0.25, 0.25, 1, 1, 1])
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        ActionLayout(wrist_translation_residual=(1.0, 1.5, 1.0))
    env = _env(EnvConfig(contract=ControlContract(observation=MARKOV, action=action)))
    env.reset()
    state = env.state()
    palm0, rot0 = state["palm_pos"][0].copy(), state["palm_rot"][0].copy()
    a = np.zeros((1, env.action_dim))
    a[:, :3] = 1.0
    for _ in range(3):
        env.step(a)
    f, l, n = rot0.T @ (env.state()["palm_pos"][0] - palm0)
    env.close()
    assert abs(l) < 0.005 and 0.02 < f < 0.04 and 0.02 < n < 0.04  # l would be 0.03 at a factor of 1


def test_early_stop_ends_hopeless_episodes_in_training_only():
    """early_stop: a hand that never touches the object ends its episode as a true terminal state at the end
    of the grasp phase (not the full 190 steps); eval's env builder turns the option off."""
    from dgz_cli.sim.evaluate import make_env

    cfg = EnvConfig(early_stop=True)
    env = _env(cfg)
    env.reset()
    ep = cfg.contract.episode
    away = np.zeros((1, env.action_dim))
    away[0, 2] = -1.0  # back off along the palm normal: never touch
    for k in range(ep.grasp_steps):
        _, _, terminated, truncated, info = env.step(away)
        if info["episode"]:
            break
    assert k == ep.grasp_steps - 1 and terminated[0] and not truncated[0]
    rec = info["episode"][0]
    assert rec["steps"] == ep.grasp_steps and not rec["touched"] and not rec["pushed"] and not rec["success"]
    env.close()
    full = make_env([(TRI, resolve_objects("box")[0])], cfg, seed=4, threads=1)
    assert not full.cfg.early_stop
    full.close()


def test_throughput_levers_reach_the_env_config():
    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.rl.config import env_config

    cfg = env_config(TrainConfig(physics_hz=200, early_stop=True))
    assert cfg.contract.episode.substeps == 10 and cfg.early_stop
    assert env_config(TrainConfig()).contract == ControlContract()  # defaults: the paper's 400 Hz, no early stop
    with pytest.raises(ValueError, match="whole multiple"):
        TrainConfig(physics_hz=250)


def test_training_settle_reaches_the_env_config():
    """settle_s (issue 11: start episodes from objects at rest) is a run option: the default is the env's 0.3 s,
    so older checkpoints (which lack the field) keep their start states, and it is range-checked."""
    from pydantic import ValidationError

    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.rl.config import env_config

    assert env_config(TrainConfig()).settle_s == EnvConfig().settle_s == 0.3
    assert env_config(TrainConfig(settle_s=2.0)).settle_s == 2.0
    for bad in (-0.1, 10.5):
        with pytest.raises(ValidationError, match="settle_s"):
            TrainConfig(settle_s=bad)
        with pytest.raises(ValidationError, match="settle_s"):  # the env field itself: a checkpoint's env too
            EnvConfig(settle_s=bad)


def test_object_orientation_is_a_run_option():
    """object_orientation (issue 11: GraspXL's upright placement) reaches the env from a run's config; the
    default stays random, so older checkpoints (which lack the field) keep their start states."""
    from pydantic import ValidationError

    from dgz_cli.rl.config import TrainConfig, env_config

    assert env_config(TrainConfig()).object_orientation == EnvConfig().object_orientation == "random"
    assert env_config(TrainConfig(object_orientation="upright")).object_orientation == "upright"
    with pytest.raises(ValidationError, match="object_orientation"):
        TrainConfig(object_orientation="sideways")


def test_train_view_trains_on_the_held_cloud_with_the_privileged_inputs(tmp_path):
    """train_view (issue 12): the training env observes the object as hardware gives it (the first frame's
    cloud held, object velocities 0) and keeps the teacher's contact and force blocks; the option is recorded in
    the checkpoint and is off by default. Moving the object after the first frame moves the sim's target and not
    the held one."""
    from dgz_cli.cli.train_cmd import build
    from dgz_cli.rl.checkpoint import read_meta
    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.sim.hardware import HardwareViewEnv
    from dgz_cli.spec.hardware_view import HardwareView

    view = HardwareView(held_cloud=True)
    run = dict(hands=("dgz_tri",), objects="box", repeat=1, steps_per_env=4, iterations=1, seed=0)
    plain, held = (build(TrainConfig(train_view=v, **run), tmp_path / name, None)
                   for v, name in ((None, "plain"), (view, "held")))
    assert type(plain.env) is GraspEnv and isinstance(held.env, HardwareViewEnv) and held.env.view == view
    lay = held.env.cfg.contract.observation
    assert lay.has("contact") and lay.has("force") and held.env.cfg == plain.env.cfg
    first = [t.env.reset(0) for t in (plain, held)]
    target, v_obj = lay.global_col("target"), lay.global_col("v_obj")
    np.testing.assert_allclose(first[1]["global"][:, target], first[0]["global"][:, target], atol=1e-6)
    for t in (plain, held):  # the object is moved 6 cm along world x after the first frame
        s = t.env.slots[0]
        s.data.qpos[s.idx.object_qadr] += 0.06
    obs = [t.env.step(np.zeros((1, t.env.action_dim)))[0] for t in (plain, held)]
    moved = np.linalg.norm((obs[0]["global"][0, target] - obs[1]["global"][0, target]) * lay.target_scale)
    assert 0.05 < moved < 0.07, moved  # the sim's target followed the object, the held one did not
    assert np.all(obs[1]["global"][:, v_obj] == 0) and np.abs(obs[0]["global"][:, v_obj]).max() > 0
    held.train()
    assert read_meta(tmp_path / "held").train.train_view == view
    assert TrainConfig().train_view is None
    for t in (plain, held):
        t.env.close()


def test_pick_roll_by_hand():
    widths = np.array([0.05, 0.08, 0.06, 0.09])
    assert pick_roll(widths) == 0                                               # narrow: the narrowest
    assert pick_roll(widths, np.array([-0.03, 0.01, 0.02, 0.0])) == 2         # clear: the narrowest of 1, 2, 3
    none_clear = np.array([-0.05, -0.02, -0.029, -0.031])
    assert pick_roll(widths, none_clear, 0.01) == 2       # none clear: the narrowest within 1 cm of the best (−0.02)
    assert pick_roll(widths, none_clear, 0.0) == 1
    assert pick_roll(widths, np.array([-0.03, 0.01, 0.02, 0.0]), 0.0, depth=0.03) == 0  # 3 cm below counts as clear


def _lowest_at_reset(env: GraspEnv) -> np.ndarray:
    """(B,) m: each slot's lowest hand collision-box corner with the grasp point moved to the object centroid."""
    out = []
    for s in env.slots:
        d, idx = s.data, s.idx
        center = d.xpos[idx.object_body] + (idx.cloud @ d.xmat[idx.object_body].reshape(3, 3).T).mean(0)
        out.append(s._lowest_at_target(d.xmat[idx.wrist_body].reshape(3, 3), center))
    return np.array(out)


@needs_assets()
def test_clear_roll_keeps_shadows_forearm_off_the_table():
    """Shadow's forearm reaches the table on tilted approaches under the narrow roll; the clear roll picks, from
    the same candidates (same seed), one at least as high on every slot and strictly higher where it matters."""
    shadow = load_spec(resolve_spec("shadow"))
    lowest = {}
    for roll in ("narrow", "clear"):
        env = GraspEnv([(shadow, resolve_objects("sphere")[0])] * 8, EnvConfig(roll=roll), seed=3, threads=1)
        env.reset(3)
        lowest[roll] = _lowest_at_reset(env)
        env.close()
    assert (lowest["clear"] >= lowest["narrow"] - 1e-9).all()
    assert (lowest["narrow"] < -0.03).any() and (lowest["clear"] > lowest["narrow"] + 0.02).any()


def test_the_env_rewards_the_objects_displacement_from_where_it_settled():
    cfg = EnvConfig(contract=ControlContract(observation=MARKOV), reward_variant="graspxl",
                    graspxl=GraspXLReward(displace=2.0))
    env = _env(cfg)
    env.reset()
    env.p0[0] -= [0.06, 0.0, 0.0]  # as if the object had settled 6 cm away from where it is now
    _, _, _, _, info = env.step(np.zeros((1, env.action_dim)))
    moved = np.linalg.norm(env.buf["xpos"][0, env.N] - env.p0[0])
    assert moved == pytest.approx(0.06, abs=0.005)
    assert info["reward_terms"]["displace"][0] == pytest.approx(-moved / cfg.graspxl.push_limit)


def test_target_noise_shifts_the_observed_target_horizontally_per_episode_in_training_only():
    """target_noise: the same start state as without it, an observed grasp target (and so the guidance's aim)
    displaced by a horizontal world offset of the order of the std, another offset in another episode, the guidance error
    shifted by the same vector; dgz eval's env builder turns it off."""
    from dgz_cli.sim.evaluate import make_env

    markov = ControlContract(observation=MARKOV)
    clean, noisy = _env(EnvConfig(contract=markov)), _env(EnvConfig(contract=markov, target_noise=0.03))
    lay = markov.observation
    shifts = []
    for episode in range(3):
        o_clean, o_noisy = (env.reset(seed=4 + episode) for env in (clean, noisy))
        s_clean, s_noisy = clean.state(), noisy.state()
        np.testing.assert_array_equal(s_clean["palm_pos"], s_noisy["palm_pos"])  # the start state is untouched
        rot = s_clean["palm_rot"][0]
        d_target = (o_noisy["global"][0, lay.global_col("target")] - o_clean["global"][0, lay.global_col("target")])
        d_guide = (o_noisy["global"][0, lay.global_col("guide")] - o_clean["global"][0, lay.global_col("guide")])
        np.testing.assert_allclose(d_target, d_guide, atol=1e-6)  # float32 observations
        world = rot @ (d_target * lay.target_scale)  # palm frame → world
        assert abs(world[2]) < 1e-5 and 0.001 < np.linalg.norm(world) < 0.15
        shifts.append(world[:2])
    assert np.linalg.norm(shifts[0] - shifts[1]) > 1e-3 and np.linalg.norm(shifts[1] - shifts[2]) > 1e-3
    for env in (clean, noisy):
        env.close()
    evaluated = make_env([(TRI, resolve_objects("box")[0])], EnvConfig(contract=markov, target_noise=0.03), seed=4,
                         threads=1)
    assert evaluated.cfg.target_noise == 0.0 and not evaluated.target_shift.any()
    evaluated.close()


def test_dynamics_noise_scales_mass_friction_and_finger_force_per_episode_and_slot_in_training_only():
    """dynamics_noise r: each slot gets its own model; every episode scales the object's mass and inertia, every
    geom's friction and the finger actuators' force limits (not the wrist's) by factors in [e^-r, e^r], other
    factors in another episode or slot; without it the slots of one pair share the compiled model, and dgz eval's
    env builder turns it off."""
    from dgz_cli.sim.evaluate import make_env

    box = resolve_objects("box")[0]
    plain = GraspEnv([(TRI, box)] * 2, EnvConfig(), seed=4, threads=1)
    assert plain.slots[0].model is plain.slots[1].model
    nominal = plain.slots[0].model
    ob = plain.slots[0].idx.object_body
    r = 0.3
    noisy = GraspEnv([(TRI, box)] * 2, EnvConfig(dynamics_noise=r), seed=4, threads=1)
    assert noisy.slots[0].model is not noisy.slots[1].model
    drawn = []
    for episode in range(2):
        noisy.reset(seed=4 + episode)
        for s in noisy.slots:
            mass, friction, force = s.dynamics
            assert all(math.exp(-r) <= f <= math.exp(r) for f in s.dynamics)
            m = s.model
            assert m.body_mass[ob] == pytest.approx(nominal.body_mass[ob] * mass)
            np.testing.assert_allclose(m.body_inertia[ob], nominal.body_inertia[ob] * mass)
            np.testing.assert_allclose(m.geom_friction, nominal.geom_friction * friction)
            np.testing.assert_allclose(m.actuator_forcerange[6:], nominal.actuator_forcerange[6:] * force)
            np.testing.assert_array_equal(m.actuator_forcerange[:6], nominal.actuator_forcerange[:6])
            assert (nominal.actuator_forcerange[6:] != 0).any()  # the finger limits exist, so the check bites
            drawn.append(s.dynamics)
    assert len({d for d in drawn}) == 4  # per slot and per episode
    noisy.step(np.zeros((2, noisy.action_dim)))
    evaluated = make_env([(TRI, box)] * 2, EnvConfig(dynamics_noise=r), seed=4, threads=1)
    assert evaluated.cfg.dynamics_noise == 0.0 and evaluated.slots[0].model is evaluated.slots[1].model
    for env in (plain, noisy, evaluated):
        env.close()


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_a_scaled_finger_force_limit_is_the_force_the_joint_gets(factor):
    """A finger driven far past an obstacle pushes with its force limit; set_dynamics' factor must reach the joint
    both ways. (MuJoCo's URDF import also clamps a joint's summed actuator force at the URDF effort; kept, it
    silently undid every factor above 1.)"""
    import mujoco

    box = resolve_objects("box")[0]
    env = GraspEnv([(TRI, box)], EnvConfig(dynamics_noise=0.3), seed=0, threads=1)
    slot = env.slots[0]
    m, d = slot.model, slot.data
    assert not m.jnt_actfrclimited[m.actuator_trnid[6:, 0]].any()  # one home: the actuator's forcerange
    a = 6 + int(np.argmax(m.actuator_forcerange[6:, 1]))
    effort = TRI.joints[a - 6].effort
    assert effort and m.actuator_forcerange[a, 1] == pytest.approx(effort)
    dof = m.jnt_dofadr[m.actuator_trnid[a, 0]]
    for scale in (1.0, factor):
        slot.set_dynamics(1.0, 1.0, scale)
        mujoco.mj_resetData(m, d)
        d.ctrl[a] = d.qpos[m.jnt_qposadr[m.actuator_trnid[a, 0]]] + 100.0  # a target the gain turns into > limit
        mujoco.mj_forward(m, d)
        assert abs(d.qfrc_actuator[dof]) == pytest.approx(scale * effort, rel=1e-6)
    env.close()


def test_keep_commands_starts_fingers_that_commanded_nothing_at_zero():
    """A checkpoint trained with ``finger_residual`` 0 never commanded its fingers: a fine-tune that turns them on
    starts their output layer at zero and their log-std at the initial value, and leaves the wrist as it was;
    going back to 0 keeps the weights (nothing to keep the command of)."""
    from dgz_cli.rl.runner import keep_commands

    torch.manual_seed(0)
    off = ControlContract(action=ActionLayout(finger_residual=0.0))
    on = ControlContract(action=ActionLayout(finger_residual=0.5))
    m = MAGCN(TINY, off)
    with torch.no_grad():
        m.node_head[-1].bias.fill_(0.4)
        m.log_std_prim.fill_(-2.0)
    wrist_before = [p.clone() for p in (m.wrist_head[-1].weight, m.wrist_head[-1].bias, m.log_std_wrist)]
    applied = keep_commands(m, off, on)
    assert applied == dict(wrist=[1.0] * 6, finger=[1.0], started_at_zero=["fingers"])
    assert torch.count_nonzero(m.node_head[-1].weight) == 0 and torch.count_nonzero(m.node_head[-1].bias) == 0
    assert torch.all(m.log_std_prim == TINY.init_log_std)
    for before, after in zip(wrist_before, (m.wrist_head[-1].weight, m.wrist_head[-1].bias, m.log_std_wrist)):
        assert torch.equal(before, after)
    with torch.no_grad():
        m.node_head[-1].bias.fill_(0.4)
    assert keep_commands(m, on, off) is None and torch.all(m.node_head[-1].bias == 0.4)
