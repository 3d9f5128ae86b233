"""`dgz distill` (issue 12): the student's history (length, reset at episode start in sim and in the runtime),
the BC loss falling on a tiny DAgger run, a student checkpoint that declares no privileged input and deploys
without flags, the hardware view's observation, and the manifest's format rules. The teacher is the shipped
policies/dgz-cpu-warmstart; everything runs on dgz_tri × sphere (no vendor assets)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from rich.console import Console

from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec

pytestmark = pytest.mark.usefixtures("one_torch_thread")
TEACHER = "dgz-cpu-warmstart"
TRI = load_spec(resolve_spec("dgz_tri"))


def make_distiller(out: Path, **cfg):
    """A Distiller of the shipped teacher on dgz_tri × sphere (one env unless ``objects`` says otherwise)."""
    from dgz_cli.cli.distill_cmd import build
    from dgz_cli.rl.distill_config import DistillConfig

    base = dict(teacher=TEACHER, hands=("dgz_tri",), objects="sphere", iterations=1, steps_per_env=20, epochs=1,
                threads=1)
    return build(DistillConfig(**{**base, **cfg}), out, None)


def make_student(out: Path, seed: int = 0, **cfg) -> Path:
    """A student checkpoint in ``out`` straight from the teacher, its memory projections randomised (so the
    history changes the actions: a test that ignored it would fail)."""
    dist = make_distiller(out, **cfg)
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for lin in (dist.model.mem_global, dist.model.mem_node):
            lin.weight.copy_(0.05 * torch.randn(lin.weight.shape, generator=gen))
    out.mkdir(parents=True, exist_ok=True)
    dist.save()
    dist.env.close()
    return out


@pytest.fixture(scope="module")
def student(tmp_path_factory) -> Path:
    return make_student(tmp_path_factory.mktemp("student") / "s")


# ---------------------------------------------------------------------- history
def test_history_has_the_last_k_steps_and_resets_per_row():
    from dgz_cli.policy.student import TokenHistory

    h = TokenHistory(2, 5, 3)
    for k in range(1, 8):
        out = h.push(np.full((2, 3), float(k)))
    assert out.shape == (2, 5, 3)
    np.testing.assert_array_equal(out[:, :, 0], [[3, 4, 5, 6, 7]] * 2)  # oldest first, the last 5
    h.reset(np.array([True, False]))
    assert not h.buf[0].any() and h.buf[1].any()


def test_student_history_in_eval_restarts_at_every_episode(student):
    """In `dgz eval`'s loop the student's history holds 1, 2, … 5, 5, … real steps, from 1 again each episode."""
    from dgz_cli.cli.sim_cmd import _policy_factory
    from dgz_cli.sim.evaluate import run_episodes
    from dgz_cli.sim.objects import resolve_objects

    make, meta = _policy_factory(str(student))
    seen: list[int] = []

    class Spy:
        def __init__(self, inner):
            self.inner = inner

        def reset(self, mask):
            self.inner.reset(mask)

        def act(self, obs):
            a = self.inner.act(obs)
            seen.append(int(self.inner.history.steps()[0]))
            return a

    run_episodes([(TRI, resolve_objects("sphere")[0])], lambda env: Spy(make(env)), 2, meta.env, 0,
                 view=meta.student.distill.view)
    n = meta.contract.episode.episode_steps
    one = [min(k + 1, 5) for k in range(n)]
    assert seen[:2 * n] == one + one


def test_runtime_reset_forgets_the_history(student):
    from dgz_cli.runtime.trained import TrainedPolicy

    class Builder:  # the observation is not used here
        pass

    pol = TrainedPolicy(student, TRI, "s", observation_builder=Builder())
    obs = _tri_obs(pol.contract)
    a1 = pol.act(obs)
    pol.act(obs)
    a3 = pol.act(obs)
    assert pol.loaded.history.steps()[0] == 3 and not np.allclose(a1, a3)  # the history matters
    pol.reset()
    assert pol.loaded.history.steps()[0] == 0
    np.testing.assert_allclose(pol.act(obs), a1, atol=1e-6)  # a new episode: as at its first step


def _tri_obs(contract) -> dict:
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.envconfig import EnvConfig

    env = GraspEnv([(TRI, resolve_objects("sphere")[0])], EnvConfig(contract=contract), threads=1)
    obs = env.reset(0)
    env.close()
    return obs


# ---------------------------------------------------------------------- BC
def test_bc_loss_falls_on_a_tiny_dagger_run(tmp_path):
    dist = make_distiller(tmp_path / "run", iterations=2, steps_per_env=30, epochs=8, learning_rate=3e-4,
                          objects="sphere,box")
    with torch.no_grad():  # start away from the teacher (imitation MSE ≈ 0.17), so there is something to learn
        gen = torch.Generator().manual_seed(1)
        for lin in (dist.model.mem_global, dist.model.mem_node):
            lin.weight.copy_(3.0 * torch.randn(lin.weight.shape, generator=gen))
    (tmp_path / "run").mkdir()
    dist.run()
    first, second = dist.history
    assert first["bc_loss"] < 0.5 * first["bc_loss_first_epoch"]
    assert second["imitation_mse"] < first["imitation_mse"]  # DAgger: the student's own states, labelled
    assert second["samples"] == 2 * 30 * 2
    assert (tmp_path / "run" / "checkpoint.yaml").is_file()


def test_settle_defaults_to_the_teachers_env_and_is_recorded(tmp_path):
    """--settle (issue 12: a held first-frame cloud needs an object at rest) overrides the teacher's settle for
    the student's rollouts and is recorded in the student's env; without it the teacher's stays."""
    for given in (None, 2.0):
        dist = make_distiller(tmp_path / str(given), **({} if given is None else dict(settle_s=given)))
        teacher_settle = dist.teacher_meta.env.settle_s
        assert dist.env.cfg.settle_s == (teacher_settle if given is None else given)
        dist.env.close()
    assert teacher_settle == 0.3


def test_options_map_to_fields_and_bad_values_name_the_option(tmp_path):
    """`given` is keyed by CLI option: --steps / --settle / --history land in steps_per_env / settle_s /
    student.history, and a bad value's error names the option the user typed, not the field."""
    from dgz_cli.cli.distill_cmd import _load_config

    cfg = _load_config(dict(teacher=TEACHER, steps=33, settle=1.5, joint_noise=0.02, history=12), tmp_path / "x",
                       False)
    assert (cfg.steps_per_env, cfg.settle_s, cfg.view.joint_noise, cfg.student.history) == (33, 1.5, 0.02, 12)
    default = _load_config(dict(teacher=TEACHER), tmp_path / "x", False)
    assert default.student.history == 5 and default.teacher_view == "sim"  # the paper's; the teacher sees the sim
    assert _load_config(dict(teacher=TEACHER, teacher_view="student"), tmp_path / "x", False).teacher_view == "student"
    with pytest.raises(DgzError, match="^--teacher-view: "):
        _load_config(dict(teacher=TEACHER, teacher_view="camera"), tmp_path / "x", False)
    with pytest.raises(DgzError, match="^--history: "):
        _load_config(dict(teacher=TEACHER, history=0), tmp_path / "x", False)
    with pytest.raises(DgzError, match="^--settle: "):
        _load_config(dict(teacher=TEACHER, settle=-1.0), tmp_path / "x", False)
    with pytest.raises(DgzError, match="^--steps: "):
        _load_config(dict(teacher=TEACHER, steps=0), tmp_path / "x", False)
    with pytest.raises(DgzError, match="^--joint-noise: "):
        _load_config(dict(teacher=TEACHER, joint_noise=-0.1), tmp_path / "x", False)


# ---------------------------------------------------------------------- checkpoint and deploy
def test_student_checkpoint_declares_no_privileged_inputs(student):
    from dgz_cli.rl.checkpoint import read_meta

    meta = read_meta(student)
    assert meta.format == 3 and meta.student is not None
    assert meta.privileged_inputs == () and not meta.contract.observation.has("contact")
    assert meta.student.teacher_layout.privileged_inputs == ("contact", "force")
    assert meta.student.distill.view.held_cloud and meta.student.distill.view.joint_noise == 0.01
    assert meta.student.init["partial"] == 1  # the first GCN layer: the teacher's columns of the kept blocks


def test_deploy_runs_a_student_without_flags(student, tmp_path):
    from dgz_cli.cli import deploy_cmd
    from dgz_cli.runtime.policy import load_policy
    from dgz_cli.runtime.steplog import read_log

    pol = load_policy(str(student), TRI)  # no allow_privileged: not refused
    assert pol.privileged_inputs == frozenset()
    log, out = tmp_path / "run.jsonl", Console(width=240, record=True)
    code = deploy_cmd.run("dgz_tri", "sim", str(student), Path("sphere"), False, False, True, log, "hold", None, out)
    assert code == 0, out.export_text()
    header, steps, end = read_log(log)
    assert end["ok"] and header["privileged_zeroed"] == [] and "fed as zeros" not in out.export_text()
    assert len([s for s in steps if s["phase"] == "grasp"]) == 120


@pytest.mark.parametrize("change,match", [(dict(format=2), "format 3 marks a student"),
                                          (dict(student=None), "format 3 marks a student")])
def test_student_format_rules(student, tmp_path, change, match):
    from dgz_cli.rl.checkpoint import read_meta

    bad = tmp_path / "bad"
    shutil.copytree(student, bad)
    meta = yaml.safe_load((bad / "checkpoint.yaml").read_text())
    for k, v in change.items():
        meta.pop(k) if v is None else meta.__setitem__(k, v)
    (bad / "checkpoint.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    with pytest.raises(DgzError, match=match):
        read_meta(bad)


# ---------------------------------------------------------------------- the hardware view
def _teacher_and_student_envs():
    """The teacher's env config, the student's (the teacher's contract without the privileged blocks) and
    dgz_tri × sphere, box: the pairs the hardware-view tests step."""
    from dgz_cli.rl.checkpoint import read_meta, resolve_checkpoint
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.hardware_view import student_contract

    tcfg = read_meta(resolve_checkpoint(TEACHER)).env
    scfg = tcfg.model_copy(update=dict(contract=student_contract(tcfg.contract)))
    return tcfg, scfg, [(TRI, o) for o in resolve_objects("sphere,box")]


def test_hardware_view_env_gives_the_teacher_its_observation_and_the_student_hardwares():
    """Without perturbation the teacher's observation is the plain env's exactly; with them, the student's
    target stays on the first frame's centroid and the object velocities read 0, and joint noise shows."""
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.hardware import HardwareViewEnv
    from dgz_cli.spec.hardware_view import HardwareView

    tcfg, scfg, pairs = _teacher_and_student_envs()
    plain = GraspEnv(pairs, tcfg, threads=1)
    clean = HardwareViewEnv(pairs, scfg, HardwareView(), teacher_layout=tcfg.contract.observation, threads=1)
    hw = HardwareViewEnv(pairs, scfg, HardwareView(joint_noise=0.01, held_cloud=True), threads=1)
    rng = np.random.default_rng(0)
    obs = [plain.reset(0), clean.reset(0), hw.reset(0)]
    lay = scfg.contract.observation
    np.testing.assert_array_equal(clean.teacher_obs["nodes"], obs[0]["nodes"])
    d, target = lay.node_col("d"), lay.global_col("target")
    # the first frame: the held cloud is the live one
    np.testing.assert_allclose(obs[2]["nodes"][..., d], obs[1]["nodes"][..., d], atol=1e-6)
    np.testing.assert_allclose(obs[2]["global"][:, target], obs[1]["global"][:, target], atol=1e-6)
    for _ in range(60):
        a = np.clip(rng.normal(0, 0.5, (2, plain.action_dim)), -1, 1)
        obs = [plain.step(a)[0], clean.step(a)[0], hw.step(a)[0]]
    np.testing.assert_array_equal(clean.teacher_obs["nodes"], obs[0]["nodes"])
    np.testing.assert_array_equal(clean.teacher_obs["global"], obs[0]["global"])
    assert np.abs(obs[2]["global"][:, lay.global_col("v_obj")]).max() == 0.0
    theta = lay.node_col("theta")
    err = np.abs(obs[2]["nodes"][..., theta] - obs[1]["nodes"][..., theta]).max()
    assert 1e-4 < err < 0.05  # noisy readings, / π
    for e in (plain, clean, hw):
        e.close()


def test_a_teacher_can_label_from_the_students_view_plus_its_privileged_inputs():
    """teacher_sees_view (dgz distill --teacher-view student): the teacher's observation is the student's
    perturbed one (held cloud, noisy joints) in the teacher's layout, with the simulator's contact and force."""
    from dgz_cli.sim.hardware import HardwareViewEnv
    from dgz_cli.sim.scripted import ScriptedGrasp
    from dgz_cli.spec.hardware_view import HardwareView

    tcfg, scfg, pairs = _teacher_and_student_envs()
    view = HardwareView(joint_noise=0.01, held_cloud=True)
    envs = [HardwareViewEnv(pairs, scfg, view, teacher_layout=tcfg.contract.observation, teacher_sees_view=sees,
                            threads=1) for sees in (False, True)]
    tl, sl = tcfg.contract.observation, scfg.contract.observation
    script = ScriptedGrasp.for_env(envs[0])  # it grasps, so the contact blocks are not all zero
    obs = [e.reset(0) for e in envs]
    touched = False
    for _ in range(80):
        a = script.act(obs[0])
        obs = [e.step(a)[0] for e in envs]
        for name, _ in sl.node:  # every student block: the student's own observation
            np.testing.assert_array_equal(envs[1].teacher_obs["nodes"][..., tl.node_col(name)],
                                          obs[1]["nodes"][..., sl.node_col(name)])
        for name, _ in sl.global_:
            np.testing.assert_array_equal(envs[1].teacher_obs["global"][:, tl.global_col(name)],
                                          obs[1]["global"][:, sl.global_col(name)])
        for name in ("contact", "force"):  # the privileged blocks: the simulator's, as the sim-view teacher gets
            np.testing.assert_array_equal(envs[1].teacher_obs["nodes"][..., tl.node_col(name)],
                                          envs[0].teacher_obs["nodes"][..., tl.node_col(name)])
        touched |= bool(envs[1].teacher_obs["nodes"][..., tl.node_col("contact")].any())
    np.testing.assert_array_equal(obs[0]["nodes"], obs[1]["nodes"])  # the student's observation is unchanged
    theta = tl.node_col("theta")
    assert np.abs(envs[1].teacher_obs["nodes"][..., theta] - envs[0].teacher_obs["nodes"][..., theta]).max() > 1e-4
    assert touched
    for e in envs:
        e.close()


def test_the_shipped_student_is_deploys_default():
    """`dgz deploy`'s --policy default is the shipped student, which declares no privileged input."""
    import inspect

    from dgz_cli.cli.app import deploy
    from dgz_cli.rl.checkpoint import read_meta, resolve_checkpoint

    default = inspect.signature(deploy).parameters["policy"].default.default
    meta = read_meta(resolve_checkpoint(default))
    assert default == "dgz-cpu-student" and meta.format == 3 and meta.privileged_inputs == ()
    assert meta.student.teacher_path == "dgz-cpu-held" and meta.student.distill.teacher_view == "student"
    assert meta.contract.guidance.aim_residual == 0.05  # the teacher's aim shift reaches deploy with the student
    assert meta.contract.start.thumb_open == 0.5  # deploy ramps to the teacher's start pose
