"""Deploying a trained MAGCN checkpoint: name resolution, the privileged-input refusal and --allow-privileged,
and full `dgz deploy` runs of the shipped policies/dgz-cpu-first on the sim and on a pty fake."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from rich.console import Console

from conftest import REPO, asset_root, needs_assets
from dgz_cli.cli import deploy_cmd
from dgz_cli.runtime.policy import load_policy
from dgz_cli.runtime.steplog import read_log
from dgz_cli.rl.checkpoint import resolve_checkpoint
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SHIPPED = "dgz-cpu-first"
TRI = load_spec(resolve_spec("dgz_tri"))


def console() -> Console:
    return Console(width=240, force_terminal=False, record=True)


@pytest.fixture(scope="module")
def points(tmp_path_factory) -> Path:
    """A 7 cm ball 8 cm in front of the palm (palm frame: f, l, n), as an --object-points file."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(400, 3))
    path = tmp_path_factory.mktemp("obj") / "ball.npy"
    np.save(path, 0.035 * v / np.linalg.norm(v, axis=1, keepdims=True) + [0.03, 0.0, 0.08])
    return path


def checkpoint_copy(tmp_path: Path, **meta_update) -> Path:
    """policies/dgz-cpu-first with its metadata changed (``None`` deletes a key)."""
    out = tmp_path / "ckpt"
    shutil.copytree(REPO / "policies" / SHIPPED, out)
    meta = yaml.safe_load((out / "checkpoint.yaml").read_text())
    for k, v in meta_update.items():
        meta.pop(k, None) if v is None else meta.__setitem__(k, v)
    (out / "checkpoint.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return out


def test_names_resolve_like_eval(tmp_path):
    assert resolve_checkpoint(SHIPPED) == REPO / "policies" / SHIPPED
    assert resolve_checkpoint(str(REPO / "policies" / SHIPPED)) == REPO / "policies" / SHIPPED
    assert resolve_checkpoint("no-such-policy") is None
    with pytest.raises(DgzError, match="unknown policy 'no-such-policy'") as info:
        load_policy("no-such-policy", TRI)
    assert "policies/" in info.value.hint


def test_a_teacher_checkpoint_is_refused_as_privileged():
    with pytest.raises(DgzError) as info:
        load_policy(SHIPPED, TRI)
    msg = info.value.message
    assert msg == f"policy '{SHIPPED}' needs privileged inputs (contact, force) that a real hand does not provide"
    assert "student policy" in info.value.hint and "--allow-privileged" in info.value.hint


def test_unknown_or_inconsistent_manifest_fields_are_refused_not_dropped(tmp_path):
    with pytest.raises(DgzError, match="field 'privileged_inputs': \\[\\] disagrees with the observation layout"):
        load_policy(str(checkpoint_copy(tmp_path / "s", privileged_inputs=[])), TRI)
    with pytest.raises(DgzError, match="unknown field\\(s\\) \\['bogus'\\]"):
        load_policy(str(checkpoint_copy(tmp_path / "u", bogus=1)), TRI)
    with pytest.raises(DgzError, match="field 'iteration'"):
        load_policy(str(checkpoint_copy(tmp_path / "i", iteration=-3)), TRI)


def test_trained_policy_acts_on_the_hardware_observation(points):
    policy = load_policy(SHIPPED, TRI, allow_privileged=True)
    builder = policy.observation_builder
    builder.reset(TRI, {"object_points": deploy_cmd.load_points(points), "rate_hz": 20.0})
    from dgz_cli.runtime.types import StepInput

    q = builder.kin.rest
    obs = builder.build(StepInput(0, None, q, np.zeros(policy.action_dim), np.zeros(6)))
    assert obs["nodes"].shape == (1, len(TRI.nodes), 23) and obs["global"].shape == (1, 16)
    a = policy.act(obs)
    assert a.shape == (6 + 3 * len(TRI.nodes),) and np.all(np.isfinite(a))


def test_deploy_refuses_without_the_flag(points):
    with pytest.raises(DgzError, match="needs privileged inputs"):
        deploy_cmd.run("dgz_tri", "sim", SHIPPED, points, False, False, True, None, "hold", None, console())
    with pytest.raises(DgzError, match="needs the object: no --object-points"):
        deploy_cmd.run("dgz_tri", "sim", SHIPPED, None, False, False, True, None, "hold", None, console(),
                       allow_privileged=True)


def test_cli_refusal_is_one_line_and_exit_1(points, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "deploy", "--hand", "dgz_tri", "--port", "sim",
                        "--policy", SHIPPED, "--object-points", str(points)], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 1, p.stderr
    lines = [line for line in p.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in p.stderr
    assert f"policy '{SHIPPED}' needs privileged inputs (contact, force)" in lines[0] and "student" in lines[0]


def check_run(log: Path, out: Console) -> list[dict]:
    text = out.export_text()
    assert "observes contact, force, which this hand cannot measure: fed as zeros" in text
    header, steps, end = read_log(log)
    assert end["ok"], end
    assert header["policy"] == SHIPPED and header["privileged_zeroed"] == ["contact", "force"]
    grasp = [s for s in steps if s["phase"] == "grasp"]
    assert header["contract"]["episode"]["grasp_steps"] == len(grasp) == 120  # the checkpoint's own protocol
    assert len([s for s in steps if s["phase"] == "lift"]) == 30 and len([s for s in steps if s["phase"] == "hold"]) == 40
    acts = np.array([s["action"] for s in grasp])
    assert np.ptp(acts, axis=0).max() > 0  # the network acts (raw normalized outputs are logged)
    assert grasp[-1]["target"] != grasp[0]["target"]
    return steps


def test_full_sim_run_with_the_flag(points, tmp_path):
    log, out = tmp_path / "sim.jsonl", console()
    code = deploy_cmd.run("dgz_tri", "sim", SHIPPED, points, False, False, True, log, "hold", None, out,
                          allow_privileged=True, arm="sim")
    assert code == 0, out.export_text()
    steps = check_run(log, out)
    z = [s["arm_target"][2] for s in steps if s["phase"] == "lift"]
    assert z[-1] - z[0] > 0.1  # the ideal arm lifted along +z


@needs_assets()
def test_full_fake_revo2_run_with_the_flag(points, tmp_path):
    log, out = tmp_path / "revo2.jsonl", console()
    code = deploy_cmd.run("revo2", None, SHIPPED, points, False, True, True, log, "hold", None, out,
                          allow_privileged=True, asset_root=str(asset_root()))
    assert code == 0, out.export_text()
    steps = check_run(log, out)
    last = steps[-1]
    assert np.max(np.abs(np.array(last["target"]) - np.array(last["measured"]))) < 0.05  # the fake tracked


def test_cli_flags_run_the_checkpoint(points, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    log = tmp_path / "cli.jsonl"
    p = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "deploy", "--hand", "dgz_tri", "--port", "sim",
                        "--policy", SHIPPED, "--object-points", str(points), "--allow-privileged", "--arm", "sim",
                        "--log", str(log)],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=180)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "fed as zeros" in p.stdout and read_log(log)[2]["ok"]
    (tmp_path / "piper_sdk.py").write_text("raise ImportError('not installed here')\n")  # as if absent
    p = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "deploy", "--hand", "dgz_tri", "--port", "sim",
                        "--policy", "close", "--arm", "piper"],
                       cwd=tmp_path, env={**env, "PYTHONPATH": f"{tmp_path}:{REPO}"}, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 1 and "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert "needs the 'piper_sdk' package, which is not installed" in p.stderr and "pip install piper_sdk" in p.stderr
    assert "connected" not in p.stdout  # refused before the hand was touched
