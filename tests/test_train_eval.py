"""`dgz train` / `dgz eval` end to end on the built-in hand and objects (no vendor assets)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from dgz_cli.cli.train_cmd import build
from dgz_cli.rl.checkpoint import LoadedPolicy, read_meta
from dgz_cli.rl.config import TrainConfig, env_config

SMOKE = dict(hands=("dgz_tri",), objects="sphere,box", repeat=2, steps_per_env=190, checkpoint_every=5, seed=0)


def _dgz(*args, cwd):
    return subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", *args], cwd=cwd, capture_output=True, text=True)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    trainer = build(TrainConfig(iterations=10, **SMOKE), out, None)
    trainer.train()
    return out, trainer


def test_training_improves_the_return(run_dir):
    history = run_dir[1].history
    first = np.mean([h["mean_step_reward"] for h in history[:2]])
    last = np.mean([h["mean_step_reward"] for h in history[-2:]])
    assert last > first, (first, last)


def test_checkpoint_roundtrip_gives_identical_actions(run_dir, tmp_path):
    """What eval and deploy load acts exactly like the model that training held in memory."""
    out, trainer = run_dir
    loaded = LoadedPolicy(out)
    meta = loaded.meta
    assert meta.iteration == 10 and set(meta.training_hands) == {"dgz_tri"}
    assert meta.contract == trainer.env.cfg.contract and meta.train == trainer.cfg
    weights = out / meta.weights
    assert weights.read_bytes()[:8] != b"\x80\x04\x95"  # not a pickle
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec
    from dgz_cli.policy.graph import to_tensors

    env = GraspEnv([(load_spec(resolve_spec("dgz_tri")), resolve_objects("sphere")[0])], meta.env, threads=1)
    obs = env.reset(1)
    trainer.model.eval()
    with torch.no_grad():
        in_memory = trainer.model(to_tensors(obs))[0].numpy()
    np.testing.assert_array_equal(loaded.act(obs), in_memory)
    assert np.abs(in_memory).max() > 0
    env.close()


def test_resume_continues_from_the_last_checkpoint(run_dir, tmp_path):
    out, original = run_dir
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    trainer = build(TrainConfig(iterations=11, **SMOKE), copy, None, resume=True)
    assert trainer.iteration == 10 and len(trainer.history) == 10
    for k, v in original.model.state_dict().items():  # the in-memory model at the end of the first run
        assert torch.equal(trainer.model.state_dict()[k], v), k
    before, after = original.ppo.optimizer.state_dict()["state"], trainer.ppo.optimizer.state_dict()["state"]
    assert before and set(before) == set(after)
    assert all(torch.equal(torch.as_tensor(before[i][n]), torch.as_tensor(after[i][n])) for i in before for n in before[i])
    assert trainer.ppo.learning_rate == original.ppo.learning_rate
    assert trainer.reward_norm.state() == original.reward_norm.state()
    trainer.train()
    assert trainer.iteration == 11 and [h["iteration"] for h in trainer.history] == list(range(1, 12))
    assert read_meta(copy).iteration == 11


def test_init_from_fine_tunes_the_checkpoint_with_its_recipe(run_dir, tmp_path):
    """--init-from: the checkpoint's run config is the default, its weights and return scale start the run
    (a fresh optimizer), and the source is recorded; a changed contract, a second warm start or a student is
    refused."""
    from dgz_cli.cli.train_cmd import _load_config
    from dgz_cli.spec.errors import DgzError

    out, original = run_dir
    cfg = _load_config({"init_from": str(out), "iterations": 1, "objects": "sphere", "repeat": 1}, None,
                       tmp_path / "ft", resume=False)
    assert cfg.hands == ("dgz_tri",) and cfg.steps_per_env == SMOKE["steps_per_env"] and cfg.objects == "sphere"
    trainer = build(cfg, tmp_path / "ft", None)
    for k, v in original.model.state_dict().items():
        assert torch.equal(trainer.model.state_dict()[k], v), k
    assert trainer.reward_norm.state() == original.reward_norm.state() and not trainer.ppo.optimizer.state
    trainer.train()
    meta = read_meta(tmp_path / "ft")
    assert meta.iteration == 1 and meta.train.init_from == str(out)
    assert meta.warm_start["checkpoint"] == str(out) and meta.warm_start["checkpoint_iteration"] == 10
    assert meta.warm_start["weights_sha256"] == read_meta(out).weights_sha256
    changed = _load_config({"init_from": str(out), "observation": "markov"}, None, tmp_path / "x", resume=False)
    with pytest.raises(DgzError, match="its control contract differs from this run's \\(at observation"):
        build(changed, tmp_path / "x", None)
    assert not (tmp_path / "x").exists()
    with pytest.raises(DgzError, match="two warm starts"):
        _load_config({"init_from": str(out), "bc_episodes": 2}, None, tmp_path / "x", resume=False)
    from conftest import REPO
    from dgz_cli.rl.checkpoint import load

    fresh = build(cfg.model_copy(update=dict(init_from=None)), tmp_path / "y", None)
    with pytest.raises(DgzError, match="is a distilled student"):
        fresh._init_from(*load(REPO / "policies" / "dgz-cpu-student"), "dgz-cpu-student")
    fresh.env.close()


def test_a_std_ceiling_lowers_a_fine_tunes_exploration_from_its_first_rollout(tmp_path):
    """``ppo.max_std``: a fine-tune starts exploring at most that std (before its first rollout, not after its
    first update), PPO keeps it within [min_std, max_std], the other weights are the checkpoint's, and the bound is
    recorded; a floor above the ceiling is refused."""
    import math

    from pydantic import ValidationError

    from dgz_cli.cli.train_cmd import _load_config
    from dgz_cli.rl.config import PPOConfig

    source = build(TrainConfig(iterations=1, init_log_std=-0.5, **SMOKE), tmp_path / "src", None)
    source.save()
    source.env.close()
    ppo = dict(TrainConfig().ppo.model_dump(), min_std=0.1, max_std=0.2)
    cfg = _load_config({"init_from": str(tmp_path / "src"), "ppo": ppo, "objects": "sphere", "repeat": 1}, None,
                       tmp_path / "ft", resume=False)
    tuned = build(cfg, tmp_path / "ft", None)
    stds = [p for k, p in tuned.model.state_dict().items() if k.startswith("log_std")]
    assert all(torch.allclose(p, torch.full_like(p, math.log(0.2))) for p in stds)  # 0.61 at the source
    for k, v in source.model.state_dict().items():
        if not k.startswith("log_std"):
            assert torch.equal(tuned.model.state_dict()[k], v), k
    tuned.train()
    for p in (tuned.model.log_std_wrist.detach(), tuned.model.log_std_prim.detach()):
        assert math.log(0.1) - 1e-6 <= float(p.min()) and float(p.max()) <= math.log(0.2) + 1e-6
    assert read_meta(tmp_path / "ft").train.ppo.max_std == 0.2
    with pytest.raises(ValidationError, match="min_std 0.3 is above max_std 0.2"):
        PPOConfig(min_std=0.3, max_std=0.2)


def test_init_from_may_turn_on_a_wrist_residual_starting_at_zero(tmp_path):
    """A fine-tune may change only the residual factors of the contract. A wrist that was no action in the
    checkpoint (``wrist_residual`` 0 with ``mask_actions``) starts with a zero-mean wrist head, so the run
    begins from the checkpoint's behaviour; every other weight is the checkpoint's."""
    from dgz_cli.cli.train_cmd import _load_config
    from dgz_cli.policy.graph import to_tensors
    from dgz_cli.spec.errors import DgzError

    source = build(TrainConfig(iterations=1, mask_actions=True, wrist_residual=0.0, **SMOKE), tmp_path / "src", None)
    with torch.no_grad():
        source.model.wrist_head[-1].bias.fill_(0.3)  # a wrist mean that would drift the palm if it were kept
    obs = source.env.reset(0)
    assert not source.model.wrist_is_action
    source.save()
    source.env.close()
    cfg = _load_config({"init_from": str(tmp_path / "src"), "wrist_residual": 0.25}, None, tmp_path / "ft", resume=False)
    assert cfg.wrist_residual == 0.25 and cfg.finger_residual == 1.0 and cfg.mask_actions
    tuned = build(cfg, tmp_path / "ft", None)
    assert tuned.model.wrist_is_action
    for k, v in source.model.state_dict().items():
        if k.startswith("wrist_head.2.") or k == "log_std_wrist":
            continue
        assert torch.equal(tuned.model.state_dict()[k], v), k
    wrist, t = tuned.model.wrist_dim, to_tensors(obs)
    with torch.no_grad():
        new_mean, old_mean = (m(t)[0] for m in (tuned.model, source.model))
        kept_head = tuned.model.wrist_head[-1](tuned.model.wrist_head[:-1](torch.zeros(1, tuned.model.wrist_head[0].in_features)))
    assert bool(tuned.model.action_valid(t)[:, :wrist].all()) and torch.count_nonzero(new_mean[:, :wrist]) == 0
    assert torch.count_nonzero(kept_head) == 0  # the 0.3 bias is not carried over
    torch.testing.assert_close(new_mean[:, wrist:], old_mean[:, wrist:], rtol=0, atol=0)  # the fingers act as before
    assert tuned.warm_start["action_rescale"]["started_at_zero"] == list(range(wrist))
    torch.testing.assert_close(tuned.model.log_std_wrist, torch.full((wrist,), tuned.model.cfg.init_log_std))
    tuned.env.close()
    # the translation factor alone is a residual factor too: a fine-tune may set it
    cfg = _load_config({"init_from": str(tmp_path / "src"), "wrist_residual": 0.25, "wrist_translation_residual": 0.0},
                       None, tmp_path / "ft2", resume=False)
    tuned2 = build(cfg, tmp_path / "ft2", None)
    assert tuned2.env.cfg.contract.action.translation_factors == (0.0, 0.0, 0.0) and tuned2.model.wrist_is_action
    assert tuned2.warm_start["action_rescale"]["started_at_zero"] == [3, 4, 5]  # the translation still commands nothing
    assert float(tuned2.model.wrist_head[-1].bias[0].detach()) == pytest.approx(0.3)
    tuned2.env.close()
    # so is the guidance's stop gap (how the wrist command is composed, not what a tensor means)
    cfg = _load_config({"init_from": str(tmp_path / "src"), "guidance_stop_gap": 0.05}, None, tmp_path / "ft3",
                       resume=False)
    tuned3 = build(cfg, tmp_path / "ft3", None)
    assert tuned3.env.cfg.contract.guidance.stop_gap == 0.05
    tuned3.env.close()
    other = _load_config({"init_from": str(tmp_path / "src"), "guidance_gain": 0.1}, None, tmp_path / "x", resume=False)
    with pytest.raises(DgzError, match=r"control contract differs from this run's \(at guidance.gain\).*only action.wrist_residual, "
                                       r"action.wrist_translation_residual, action.finger_residual, "
                                       r"guidance.stop_gap, guidance.aim_residual, guidance.aim_axes may change"):
        build(other, tmp_path / "x", None)


def test_init_from_keeps_the_checkpoints_commands_when_residual_factors_change(tmp_path):
    """Raising the residual factors and the aim range in a fine-tune (finger 0.5 → 1, wrist 0.25 → 1, aim 5 → 8
    cm) scales the actor's outputs and stds so that the first rollout commands what the checkpoint did: finger
    means halve (0.015 rad × 0.5 / 0.015 rad × 1), the rotation means quarter, the aim means × 0.25 × 0.05 / 0.08;
    the ratios are recorded."""
    from dgz_cli.cli.train_cmd import _load_config
    from dgz_cli.policy.graph import to_tensors

    source = build(TrainConfig(iterations=1, finger_residual=0.5, wrist_residual=0.25, guidance_gain=0.05,
                               guidance_aim_residual=0.05, **SMOKE), tmp_path / "src", None)
    with torch.no_grad():  # outputs well away from zero on every dim
        source.model.wrist_head[-1].bias.copy_(torch.linspace(-0.6, 0.6, 6))
        source.model.node_head[-1].bias.fill_(0.4)
    obs = source.env.reset(0)
    source.save()
    source.env.close()
    cfg = _load_config({"init_from": str(tmp_path / "src"), "finger_residual": 1.0, "wrist_residual": 1.0,
                        "guidance_aim_residual": 0.08}, None, tmp_path / "ft", resume=False)
    tuned = build(cfg, tmp_path / "ft", None)
    t = to_tensors(obs)
    with torch.no_grad():
        (old_mean, old_log_std, _), (new_mean, new_log_std, _) = source.model(t), tuned.model(t)
    expected = np.array([0.25 * 0.05 / 0.08] * 3 + [0.25] * 3)
    torch.testing.assert_close(new_mean[:, :6], old_mean[:, :6] * torch.as_tensor(expected, dtype=torch.float32))
    torch.testing.assert_close(new_mean[:, 6:], old_mean[:, 6:] * 0.5)
    valid = source.model.action_valid(t)
    ratio = np.concatenate([expected, np.full(old_mean.shape[1] - 6, 0.5)])
    torch.testing.assert_close((new_log_std - old_log_std)[valid],
                               torch.log(torch.as_tensor(ratio, dtype=torch.float32)).expand_as(valid)[valid])
    old_units, new_units = source.env.cfg.contract.action_units(), tuned.env.cfg.contract.action_units()
    assert old_units[0] == new_units[0] == ("aim",) * 3 + ("velocity",) * 3
    torch.testing.assert_close(new_mean[:, :6] * torch.as_tensor(new_units[1], dtype=torch.float32),
                               old_mean[:, :6] * torch.as_tensor(old_units[1], dtype=torch.float32))
    assert tuned.warm_start["action_rescale"] == dict(wrist=[round(float(x), 6) for x in expected], finger=[0.5])
    assert bool((old_mean[:, :6] != 0).all()) and bool((old_mean[:, 6:][valid[:, 6:]] != 0).all())
    tuned.env.close()
    same = build(_load_config({"init_from": str(tmp_path / "src")}, None, tmp_path / "same", resume=False),
                 tmp_path / "same", None)
    assert "action_rescale" not in same.warm_start
    same.env.close()
    # a translation that turns from a velocity into an aim shift keeps its weights; the rotation still scales
    velocity = build(TrainConfig(iterations=1, wrist_residual=0.5, guidance_gain=0.05, **SMOKE), tmp_path / "v", None)
    velocity.save()
    velocity.env.close()
    aimed = build(_load_config({"init_from": str(tmp_path / "v"), "wrist_residual": 1.0, "guidance_aim_residual": 0.08},
                               None, tmp_path / "va", resume=False), tmp_path / "va", None)
    assert aimed.warm_start["action_rescale"] == dict(wrist=[1.0] * 3 + [0.5] * 3, finger=[1.0])
    aimed.env.close()


def test_resume_refuses_another_preset(run_dir, tmp_path):
    out, _ = run_dir
    res = _dgz("train", "--hands", "dgz_tri", "--objects", "sphere,box", "--out", str(out), "--resume",
               "--preset", "paper", cwd=tmp_path)
    assert res.returncode == 1 and "differs from the requested one" in res.stderr and "Traceback" not in res.stderr


def test_eval_json_and_zero_shot_refusal(run_dir, tmp_path):
    out, _ = run_dir
    res = _dgz("eval", "--policy", str(out), "--hand", "dgz_tri", "--zero-shot", "--objects", "sphere", cwd=tmp_path)
    assert res.returncode == 1 and "was a training hand" in res.stderr
    js = tmp_path / "r.json"
    res = _dgz("eval", "--policy", str(out), "--hand", "dgz_tri", "--objects", "sphere,box", "--trials", "2",
               "--json", str(js), "--csv", str(tmp_path / "r.csv"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    data = json.loads(js.read_text())
    hand = data["hands"]["dgz_tri"]
    assert 0.0 <= hand["success_rate"] <= 1.0 and hand["episodes"] == 4
    assert set(hand["objects"]) == {"sphere", "box"} and all(o["trials"] == 2 for o in hand["objects"].values())
    assert data["protocol"]["lift_height_m"] == 0.5 and data["protocol"]["hold_s"] == 2.0
    assert data["training_hands"] == ["dgz_tri"]
    rows = (tmp_path / "r.csv").read_text().splitlines()
    assert rows[0].startswith("hand,object,trial,success,failure") and len(rows) == 5
    res = _dgz("eval", "--table", str(js), cwd=tmp_path)
    assert res.returncode == 0 and "dgz_tri (train)" in res.stdout


@pytest.mark.parametrize("args,message", [
    (("--preset", "huge"), "is not a MAGCN preset"),
    (("--ablation", "bogus"), "--ablation"),
    (("--hands", "nohand"), "unknown hand 'nohand'"),
    (("--bogus-option",), "No such option"),
    (("--init-from", "nowhere"), "--init-from 'nowhere': no such checkpoint"),
])
def test_train_bad_options(tmp_path, args, message):
    res = _dgz("train", "--out", str(tmp_path / "run"), *args, cwd=tmp_path)
    assert res.returncode != 0 and message in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "run").exists()


_REAL_TRAINING_HANDS = {"allegro", "shadow", "schunk_svh", "ability"}
# dgz-cpu-variants, dgz-cpu-aim and dgz-cpu-held also trained on one generated variant of each real hand (`dgz hands generate --variants-of`)
_E19_VARIANTS = {"allegro_v19_0000", "shadow_v20_0000", "schunk_svh_v21_0000", "ability_v22_0000"}


@pytest.mark.parametrize("name, training_hands", [
    *((n, _REAL_TRAINING_HANDS) for n in ("dgz-cpu-first", "dgz-cpu-warmstart", "dgz-cpu-guided", "dgz-cpu-residual",
                                          "dgz-cpu-residual-nocap", "dgz-cpu-thumb-open", "dgz-cpu-ycb45")),
    ("dgz-cpu-variants", _REAL_TRAINING_HANDS | _E19_VARIANTS),
    ("dgz-cpu-aim", _REAL_TRAINING_HANDS | _E19_VARIANTS),
    ("dgz-cpu-held", _REAL_TRAINING_HANDS | _E19_VARIANTS),
])
def test_shipped_policy_loads_and_refuses_its_training_hands(tmp_path, name, training_hands):
    from conftest import REPO
    from dgz_cli.policy.graph import to_tensors
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    path = REPO / "policies" / name
    loaded = LoadedPolicy(path)  # the first two are format 1, migrated on load
    meta = loaded.meta
    assert set(meta.training_hands) == training_hands
    assert meta.contract.action.finger_scale == 0.015 and meta.contract.episode.grasp_steps == 120
    env = GraspEnv([(load_spec(resolve_spec("dgz_tri")), resolve_objects("box")[0])], meta.env, threads=1)
    mean = loaded.act(env.reset(0))
    env.close()
    assert mean.shape == (1, env.action_dim) and np.isfinite(mean).all()
    assert (path / "MODEL_CARD.md").is_file()
    res = _dgz("eval", "--policy", name, "--hand", "allegro", "--zero-shot", cwd=tmp_path)
    assert res.returncode == 1 and "allegro was a training hand" in res.stderr


def test_run_config_file_sets_ppo_and_the_cli_overrides_it(tmp_path):
    """One source of defaults: TrainConfig; a --config YAML may set any field (PPO included), options win."""
    from dgz_cli.cli.train_cmd import _load_config
    from dgz_cli.spec.errors import DgzError

    conf = tmp_path / "run.yaml"
    conf.write_text("iterations: 7\nppo:\n  num_epochs: 2\n  entropy_coef: 0.001\n")
    cfg = _load_config({"iterations": 3}, conf, tmp_path / "out", resume=False)
    assert cfg.iterations == 3 and cfg.ppo.num_epochs == 2 and cfg.ppo.entropy_coef == 0.001
    assert cfg.repeat == TrainConfig().repeat
    trainer = build(cfg.model_copy(update=dict(SMOKE, objects="sphere", repeat=1)), tmp_path / "out", None)
    assert trainer.ppo.cfg.num_epochs == 2 and trainer.meta().train.ppo.entropy_coef == 0.001
    trainer.env.close()
    conf.write_text("ppo:\n  num_epochs: 0\n")
    with pytest.raises(DgzError, match="run.yaml: --ppo.num-epochs"):
        _load_config({}, conf, tmp_path / "out", resume=False)
    # the contract's cross-field rules are config errors too (one line, before any env is built)
    conf.write_text("guidance_aim_residual: 0.05\n")
    with pytest.raises(DgzError, match=r"run config: guidance.aim_residual .* needs guidance.gain > 0"):
        _load_config({}, conf, tmp_path / "out", resume=False)
    conf.write_text("closing_prior: true\n")
    with pytest.raises(DgzError, match="run config: the closing prior reads the 'phase' block"):
        _load_config({}, conf, tmp_path / "out", resume=False)
    # the aim shift's palm axes reach the contract the env and deploy read
    conf.write_text("guidance_gain: 0.05\nguidance_aim_residual: 0.05\nguidance_aim_axes: [false, true, false]\n")
    guidance = env_config(_load_config({}, conf, tmp_path / "out", resume=False)).contract.guidance
    assert guidance.aim_residual == 0.05 and guidance.aim_axes == (False, True, False)


def test_cli_defaults_come_from_the_config_model():
    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "train", "--help"], capture_output=True, text=True,
                         env={"COLUMNS": "250", "PATH": "/usr/bin:/bin"})
    text = " ".join(res.stdout.split())
    assert f"(default: {TrainConfig().iterations})" in text and f"(default: {TrainConfig().repeat})" in text
