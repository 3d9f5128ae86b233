"""r_lift (not in the paper, weight 0 by default): by hand, and in the env on a carried object."""

from __future__ import annotations

import numpy as np
import pytest

from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.spec.envconfig import EnvConfig, RewardWeights
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.reward import reward_terms, total
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def _terms(rise, lifting):
    b = len(rise)
    zeros = np.zeros((b, 1, 3))
    return reward_terms(zeros, np.zeros((b, 1), bool), np.zeros((b, 1)), np.zeros((b, 1)), zeros, np.ones((b, 1, 3)),
                        np.ones((b, 1), bool), f0=1.0, rise=np.array(rise), lifting=np.array(lifting), lift_height=0.5)


def test_lift_term_by_hand():
    t = _terms([0.25, 0.8, -0.1, 0.25], [True, True, True, False])
    np.testing.assert_allclose(t["lift"], [0.5, 1.0, 0.0, 0.0])  # fraction of 0.5 m, clipped, only when lifting
    assert total(t, RewardWeights())[0] == 0.0  # the paper's weights ignore it
    assert total(t, RewardWeights(lift=4.0))[0] == pytest.approx(2.0)


def test_env_rewards_a_carried_object_only_with_a_lift_weight():
    cfg = EnvConfig(contract=ControlContract(episode=EpisodeProtocol(hold_s=0.5)), reward=RewardWeights(lift=2.0))
    env = GraspEnv([(load_spec(resolve_spec("dgz_tri")), resolve_objects("sphere")[0])], cfg, seed=1, threads=1)
    env.reset()
    s, lifts = env.slots[0], []
    for _ in range(cfg.contract.episode.episode_steps):
        d = s.data  # carry the object just below the palm
        palm = d.xpos[s.idx.palm_body] + d.xmat[s.idx.palm_body].reshape(3, 3) @ s.idx.palm_center
        d.qpos[s.idx.object_qadr:s.idx.object_qadr + 3] = palm - np.array([0, 0, 0.1])
        d.qvel[s.idx.object_dadr:s.idx.object_dadr + 6] = 0.0
        _, _, _, _, info = env.step(np.zeros((1, env.action_dim)))
        lifts.append(float(info["reward_terms"]["lift"][0]))
    env.close()
    assert lifts[cfg.contract.episode.grasp_steps - 1] == 0.0  # nothing during the grasp phase
    assert lifts[-1] == pytest.approx(1.0)  # carried the full lift height
    assert info["episode"][0]["success"] and info["episode"][0]["r_lift"] == pytest.approx(np.mean(lifts))


def test_training_config_carries_the_lift_weight_into_the_env():
    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.rl.config import env_config

    assert env_config(TrainConfig()).reward == RewardWeights()  # the paper's reward by default
    assert env_config(TrainConfig(lift_weight=50.0)).reward.lift == 50.0
