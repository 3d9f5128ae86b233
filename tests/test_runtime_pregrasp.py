"""The control contract's start pose (:class:`StartPose`): the rule on every shipped hand, checked against the
onboarding forward kinematics (an independent path: URDF mimics through onboard.urdf, not the spec's mimic
rows); the simulator resets to it, and the deploy ramp ends at it, so training and deploy start alike."""

from __future__ import annotations

import numpy as np
import pytest
from rich.console import Console

from conftest import asset_root, needs_assets, shipped_specs
from dgz_cli.cli import deploy_cmd
from dgz_cli.hw.sim_hand import SimHand
from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.policy import ClosePolicy
from dgz_cli.runtime.pregrasp import deploy_start_pose
from dgz_cli.runtime.steplog import read_log
from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol, StartPose
from dgz_cli.spec.io import load_spec

OPEN = StartPose(thumb_open=1.0)


def thumb_tip(spec, q: np.ndarray) -> np.ndarray:
    """(3,) thumb fingertip anchor in the URDF root frame, by the onboarding Poser."""
    from dgz_cli.onboard.compile import Poser, compile_model
    from dgz_cli.onboard.urdf import load_kinematics

    kin = load_kinematics(resolve_urdf(spec.provenance.urdf, str(asset_root()) if asset_root() else None),
                          spec.provenance.xacro_args)
    poser = Poser(kin, compile_model(kin))
    poser.pose({r.joint: float(v) for r, v in zip(spec.joints, q)})
    (tip,) = [n for n in spec.nodes if n.type == "fingertip" and n.finger == "thumb"]
    return poser.link_pos(tip.anchor_link, np.array(tip.anchor_point))


def rest(spec) -> np.ndarray:
    return np.clip(0.0, [r.lower for r in spec.joints], [r.upper for r in spec.joints])


def test_default_start_is_the_rest_pose():
    """Every checkpoint trained before the start pose existed has no `start` in its contract: rest, as trained."""
    spec = load_spec(resolve_spec("dgz_tri"))
    np.testing.assert_array_equal(StartPose().pose(spec), rest(spec))
    assert ControlContract.model_validate({}).start == StartPose()


@pytest.mark.parametrize("path", shipped_specs(), ids=lambda p: p.parent.name)
def test_thumb_open_moves_exactly_the_thumb_abd_joints(path):
    spec = load_spec(path)
    lo, hi = np.array([[r.lower, r.upper] for r in spec.joints]).T
    thumb = {n.id for n in spec.nodes if n.finger == "thumb"}
    for fraction in (0.5, 1.0):
        q = StartPose(thumb_open=fraction).pose(spec)
        assert np.all(q >= lo) and np.all(q <= hi)
        for i, r in enumerate(spec.joints):
            if r.node in thumb and r.primitive.value == "ABD":
                limit = hi[i] if r.sign > 0 else lo[i]  # +ABD opens the thumb away from the index (design.md)
                assert q[i] == pytest.approx(rest(spec)[i] + fraction * (limit - rest(spec)[i])), r.joint
            else:
                assert q[i] == rest(spec)[i], r.joint
    with_rot = StartPose(thumb_open=1.0, thumb_primitives=("ABD", "ROT")).pose(spec)
    for i, r in enumerate(spec.joints):
        if r.node in thumb and r.primitive.value == "ROT":
            assert with_rot[i] == (hi[i] if r.sign > 0 else lo[i]), r.joint


@needs_assets()
@pytest.mark.parametrize("hand", ["allegro", "shadow", "ability", "leap", "inspire", "revo2"])
def test_the_opened_thumb_tip_really_moves(hand):
    """On every hand with a thumb ABD joint the tip travels ≥ 2 cm (through the URDF, not the spec)."""
    spec = load_spec(resolve_spec(hand))
    moved = np.linalg.norm(thumb_tip(spec, OPEN.pose(spec)) - thumb_tip(spec, rest(spec)))
    assert moved > 0.02, (hand, moved)


@needs_assets()
def test_the_simulator_resets_to_the_contract_start_pose():
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.envconfig import EnvConfig

    spec = load_spec(resolve_spec("inspire"))
    cfg = EnvConfig(contract=ControlContract(start=OPEN))
    env = GraspEnv([(spec, resolve_objects("sphere")[0])], cfg, threads=1)
    env.reset(0)
    slot = env.slots[0]
    np.testing.assert_allclose(slot.data.qpos[slot.idx.hand_qadr], OPEN.pose(spec), atol=1e-4)  # after settling
    np.testing.assert_allclose(env.targets[0, :slot.n_joints], OPEN.pose(spec), atol=1e-9)
    env.close()


@needs_assets()
def test_deploy_ramp_ends_at_the_contract_start_pose(tmp_path):
    spec = load_spec(resolve_spec("leap"))
    log = tmp_path / "leap.jsonl"
    out = Console(width=200, record=True)
    contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=1, lift_steps=0, hold_s=0.0),
                               start=OPEN)
    expect = deploy_start_pose(spec, contract)
    assert np.any(expect != rest(spec))
    code = deploy_cmd.run("leap", "sim", "close", None, False, False, True, log, "hold", None, out, contract=contract,
                          asset_root=str(asset_root()))
    assert code == 0, out.export_text()
    header, steps, _ = read_log(log)
    ramp = [s for s in steps if s["phase"] == "ramp"]
    np.testing.assert_allclose(header["start_pose"], expect, atol=1e-6)
    np.testing.assert_allclose(ramp[-1]["target"], expect, atol=1e-6)
    np.testing.assert_allclose(ramp[-1]["measured"], expect, atol=0.05)  # the sim hand got there
    step = np.abs(np.diff(np.array([s["target"] for s in ramp]), axis=0)).max()
    assert step <= 0.3 / 100.0 + 1e-9  # 0.3 rad/s at most


def test_hand_file_entries_override_the_contract_start_pose():
    spec = load_spec(resolve_spec("dgz_tri"))
    name = spec.joints[0].joint
    q = deploy_start_pose(spec, ControlContract(start=OPEN), {name: 1e3})
    assert q[0] == spec.joints[0].upper  # clipped into the limits
    np.testing.assert_array_equal(q[1:], OPEN.pose(spec)[1:])


def test_ramp_goal_is_clipped_to_device_limits(tmp_path):
    from dgz_cli.runtime.steplog import StepLogger

    class Narrow(SimHand):
        def limits(self):
            return self.lo + 0.1 * (self.hi - self.lo), self.hi - 0.3 * (self.hi - self.lo)

    spec = load_spec(resolve_spec("dgz_tri"))
    hi = np.array([r.upper for r in spec.joints])
    log = StepLogger(tmp_path / "ramp.jsonl")
    log.header(spec=spec.name, joints=[r.joint for r in spec.joints], rate_hz=100.0)
    with Narrow(spec, control_dt=0.01) as hand:
        contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=1, lift_steps=0, hold_s=0.0))
        res = Runner(hand, spec, ClosePolicy(spec, contract, flex=0.0), RunConfig(contract=contract, ramp_speed=3.0),
                     logger=log).run(hi)
        hi_d = hand.limits()[1]
    log.close()
    assert res.ok and res.ramp_steps > 1
    ramp = [s for s in read_log(tmp_path / "ramp.jsonl")[1] if s["phase"] == "ramp"]
    np.testing.assert_allclose(ramp[-1]["target"], hi_d, atol=1e-6)  # the narrower (device) limit, not the spec's
