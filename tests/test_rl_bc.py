"""Behaviour-cloning warm start: returns by hand, the clone imitates the scripted grasp, the run records it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dgz_cli.cli.train_cmd import build
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.policy.presets import get_preset
from dgz_cli.rl import bc
from dgz_cli.rl.config import TrainConfig
from dgz_cli.rl.normalize import ReturnNormalizer
from dgz_cli.rl.checkpoint import read_meta
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def test_discounted_returns_by_hand():
    r = np.array([[1.0, 2.0], [1.0, 0.0], [1.0, 4.0]])
    done = np.array([[False, False], [True, False], [False, False]])
    g = bc.discounted_returns(r, done, 0.5)
    # slot 0: the episode ends at t=1, so G_1 = 1, G_0 = 1 + 0.5·1; G_2 = 1 (nothing after)
    # slot 1: G_2 = 4, G_1 = 0 + 0.5·4 = 2, G_0 = 2 + 0.5·2 = 3
    np.testing.assert_allclose(g, [[1.5, 3.0], [1.0, 2.0], [1.0, 4.0]])


@pytest.fixture(scope="module")
def demos():
    spec = load_spec(resolve_spec("dgz_tri"))
    env = GraspEnv([(spec, o) for o in resolve_objects("sphere,box")], threads=1)
    d = bc.collect(env, ScriptedGrasp(env.N, env.grasp_offset), 1, ReturnNormalizer(env.B, 0.996), 0.996, seed=3)
    env.close()
    return d


def test_collect_shapes_and_whole_episodes(demos):
    T, B = demos.actions.shape[:2]
    assert (T, B) == (190, 2) and demos.episodes == 2
    assert demos.nodes.shape[:2] == (T, B) and demos.global_.shape == (T, B, 16)
    assert torch.isfinite(demos.returns).all()
    # the scripted grasp approaches first (wrist +n), then closes (+FLEX on active axes)
    assert (demos.actions[0, :, 2] == 1).all()
    assert (demos.actions[-1, :, 6:] > 0).any()


class _Frozen(torch.nn.Module):
    """A student that never moves: (B, A) zero means."""

    def act(self, obs):
        b, n = obs["node_valid"].shape
        return torch.zeros(b, 6 + 3 * n)


def _first_closing_step(d: bc.Demonstrations) -> int:
    return int(torch.nonzero((d.actions[:, 0, 6:] > 0).any(-1))[0])


def test_dagger_executes_the_student_and_labels_with_the_teacher(demos):
    spec = load_spec(resolve_spec("dgz_tri"))
    env = GraspEnv([(spec, o) for o in resolve_objects("sphere,box")], threads=1)
    d = bc.collect(env, ScriptedGrasp(env.N, env.grasp_offset), 1, ReturnNormalizer(env.B, 0.996), 0.996, seed=3,
                   student=_Frozen())
    env.close()
    # the teacher labels "approach" first in both; a hand that does not move stalls at once and the
    # teacher switches to closing after 3 steps, while when it acts itself it approaches for longer
    assert (d.actions[0, :, 2] == 1).all()
    assert _first_closing_step(d) <= 5 < 10 < _first_closing_step(demos)
    assert d.success_rate == 0.0
    both = bc.Demonstrations.concat([demos, d])
    assert both.actions.shape[0] == 2 * demos.actions.shape[0] and both.episodes == 4


def test_pretrain_makes_the_policy_imitate_the_teacher(demos):
    torch.manual_seed(0)
    model = MAGCN(get_preset("compact"))
    T, B = demos.actions.shape[:2]
    t, b = torch.arange(T).repeat_interleave(B), torch.arange(B).repeat(T)
    obs = demos.obs(t, b)
    av = model.action_valid(obs).float()

    def error() -> float:
        with torch.no_grad():
            mean = model(obs)[0]
        return float((((mean - demos.actions[t, b]) ** 2) * av).sum() / av.sum())

    before = error()
    stats = bc.pretrain(model, demos, epochs=30, mini_batch=128, learning_rate=1e-3, log_std=-1.2, seed=0)
    after = error()
    assert after < 0.25 * before, (before, after)
    assert abs(stats["bc_action_loss"] - after) < 0.1
    assert torch.allclose(model.log_std_prim, torch.full_like(model.log_std_prim, -1.2))


def test_training_with_warm_start_records_it(tmp_path):
    cfg = TrainConfig(hands=("dgz_tri",), objects="sphere", repeat=1, steps_per_env=20, iterations=1, seed=0,
                      bc_episodes=1, bc_epochs=2, bc_dagger_rounds=1)
    seen = []
    build(cfg, tmp_path, None, on_warm_start=seen.append).train()
    meta = read_meta(tmp_path)
    assert meta.train.bc_episodes == 1 and meta.warm_start["teacher"] == "scripted"
    assert meta.warm_start["episodes"] == 2 and seen == [meta.warm_start]
    assert len(meta.warm_start["clone_success_rates"]) == 1
    assert meta.privileged_inputs == ("contact", "force")


def test_git_revision_marks_a_dirty_tree(tmp_path):
    import subprocess

    from dgz_cli.rl.checkpoint import git_revision

    assert git_revision(tmp_path) is None  # not a git checkout
    run = lambda *a: subprocess.run(["git", *a], cwd=tmp_path, check=True, capture_output=True)  # noqa: E731
    run("init", "-q")
    (tmp_path / "f.txt").write_text("a")
    run("add", "f.txt")
    run("-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qm", "x")
    clean = git_revision(tmp_path)
    assert len(clean) == 40
    (tmp_path / "f.txt").write_text("b")
    assert git_revision(tmp_path) == clean + "-dirty"
