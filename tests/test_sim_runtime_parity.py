"""The deploy runtime on its MuJoCo backend reproduces `dgz eval` step for step (issue: one contract from
simulation to the real hand). Same hand, object and seed: the action sequences of a whole episode agree to
float tolerance, for the scripted grasp and for a trained checkpoint, and so do the outcomes."""

from __future__ import annotations

import numpy as np
import pytest
from rich.console import Console

from dgz_cli.cli import deploy_cmd
from dgz_cli.runtime.steplog import read_log
from dgz_cli.sim.evaluate import run_episodes
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ActionLayout, ClosingPrior,
                                   ControlContract, ObservationLayout, WristGuidance)
from dgz_cli.spec.io import load_spec

HAND, OBJECT, SEED = "dgz_tri", "sphere", 3


class Recorder:
    """Wraps an eval policy; keeps slot 0's actions of its first episode."""

    def __init__(self, inner, steps: int) -> None:
        self.inner, self.steps, self.actions = inner, steps, []

    def reset(self, mask) -> None:
        self.inner.reset(mask)

    def act(self, obs):
        a = np.asarray(self.inner.act(obs))
        if len(self.actions) < self.steps:
            self.actions.append(a[0].astype(float).copy())
        return a


LEVERS = ControlContract(  # issue 11's levers that act through the contract: all of them on
    observation=ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS),
    action=ActionLayout(finger_max_lead=0.05, mask_actions=True), guidance=WristGuidance(gain=0.05, stop_gap=0.05),
    prior=ClosingPrior(enabled=True))


def _eval_actions(policy: str, contract=None):
    from dgz_cli.cli.sim_cmd import _policy_factory

    make, meta = _policy_factory(policy)
    view = meta.student.distill.view if meta is not None and meta.student is not None else None
    from dgz_cli.spec.envconfig import EnvConfig

    cfg = meta.env if meta is not None else EnvConfig(contract=contract or ControlContract())
    rec = {}

    def factory(env):
        rec["p"] = Recorder(make(env), cfg.contract.episode.episode_steps)
        return rec["p"]

    records = run_episodes([(load_spec(resolve_spec(HAND)), resolve_objects(OBJECT)[0])], factory, 1, cfg, SEED,
                           view=view)
    return np.array(rec["p"].actions), records[0]


def _deploy_actions(policy: str, tmp_path, contract=None):
    log = tmp_path / "run.jsonl"
    code = deploy_cmd.run("sim", None, policy, None, False, False, True, log, "hold", None,
                          Console(file=open(tmp_path / "out.txt", "w"), width=200), sim_hand=HAND, sim_object=OBJECT,
                          seed=SEED, contract=contract)
    assert code == 0
    header, steps, end = read_log(log)
    return np.array([s["action"] for s in steps if s["phase"] in ("grasp", "lift", "hold")]), header, end


@pytest.mark.parametrize("policy,contract", [("scripted", None), ("dgz-cpu-warmstart", None), ("scripted", LEVERS),
                                            ("dgz-cpu-residual", None)],
                         ids=["scripted", "checkpoint", "scripted-guided-markov", "checkpoint-guided-prior-residual"])
def test_deploy_on_sim_reproduces_eval(policy, contract, tmp_path):
    expected, record = _eval_actions(policy, contract)
    got, header, end = _deploy_actions(policy, tmp_path, contract)
    assert got.shape == expected.shape == (190, 6 + 3 * len(load_spec(resolve_spec(HAND)).nodes))
    np.testing.assert_allclose(got, expected, atol=1e-5, rtol=0)
    assert np.ptp(expected[:, 6:], axis=0).max() > 0.1  # the fingers really move: not a vacuous comparison
    assert header["contract"]["episode"]["grasp_steps"] == 120
    out = (tmp_path / "out.txt").read_text()
    assert ("episode succeeded" if record["success"] else "episode failed") in out


def test_deploy_on_sim_reproduces_eval_for_a_student(tmp_path):
    """A distilled student (issue 12) under its hardware view (joint noise, held cloud): the same observation
    gives the same action in `dgz eval` and in the runtime, its history reset at the episode's start in both."""
    from test_distill import make_student

    student = str(make_student(tmp_path / "student"))
    expected, record = _eval_actions(student)
    got, header, end = _deploy_actions(student, tmp_path)
    assert got.shape == expected.shape == (190, 6 + 3 * len(load_spec(resolve_spec(HAND)).nodes))
    np.testing.assert_allclose(got, expected, atol=1e-5, rtol=0)
    assert np.ptp(expected[:, 6:], axis=0).max() > 0.1
    assert header["privileged_zeroed"] == []


def test_deploy_on_sim_reproduces_eval_with_an_aim_residual(tmp_path):
    """The shipped `dgz-cpu-aim`, whose contract turns the wrist's translation action into a shift of the
    guidance's aim (``guidance.aim_residual``): the runtime composes the wrist command as the simulator does, so
    the palm, and with it every later observation and action, stays the same."""
    from dgz_cli.rl.checkpoint import load, resolve_checkpoint, save

    tensors, meta = load(resolve_checkpoint("dgz-cpu-aim"))  # the folder `_eval_actions` and deploy resolve too
    assert meta.env.contract.guidance.aim_residual == 0.05
    expected, record = _eval_actions("dgz-cpu-aim")
    got, header, end = _deploy_actions("dgz-cpu-aim", tmp_path)
    assert header["contract"]["guidance"]["aim_residual"] == 0.05
    np.testing.assert_allclose(got, expected, atol=1e-5, rtol=0)
    assert np.abs(expected[:120, :3]).max() > 0.05  # the policy's translation actions are not all zero
    # the same weights with the translation as a wrist velocity instead: the aim changes the episode
    contract = meta.env.contract.model_copy(update=dict(
        guidance=meta.env.contract.guidance.model_copy(update=dict(aim_residual=None))))
    ControlContract.model_validate(contract.model_dump())
    save(tmp_path / "velocity", tensors,
         meta.model_copy(update=dict(env=meta.env.model_copy(update=dict(contract=contract)))))
    base, _ = _eval_actions(str(tmp_path / "velocity"))
    assert np.abs(base - expected).max() > 1e-3
