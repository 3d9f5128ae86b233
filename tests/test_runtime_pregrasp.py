"""The thumb-open start pose (paper Supp. S2), checked with the onboarding forward kinematics (an independent
path: URDF mimics through onboard.urdf, not the spec's mimic rows), and the deploy ramp that ends there."""

from __future__ import annotations

import numpy as np
import pytest
from rich.console import Console

from conftest import asset_root, needs_assets, shipped_specs
from dgz_cli.cli import deploy_cmd
from dgz_cli.hw.sim_hand import SimHand
from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.policy import ClosePolicy
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.runtime.pregrasp import deploy_start_pose, thumb_open_pose
from dgz_cli.runtime.steplog import read_log
from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
from dgz_cli.spec.io import load_spec

OPENS = ["leap", "allegro", "shadow", "schunk_svh"]  # hands whose rest pose leaves room to open the thumb


def spread(spec, q: np.ndarray) -> float:
    """Mean distance (m) thumb tip → other fingertips, by the onboarding Poser."""
    from dgz_cli.onboard.compile import Poser, compile_model
    from dgz_cli.onboard.urdf import load_kinematics

    kin = load_kinematics(resolve_urdf(spec.provenance.urdf, str(asset_root()) if asset_root() else None),
                          spec.provenance.xacro_args)
    poser = Poser(kin, compile_model(kin))
    poser.pose({r.joint: float(v) for r, v in zip(spec.joints, q)})
    tips = {n.finger: poser.link_pos(n.anchor_link, np.array(n.anchor_point)) for n in spec.nodes
            if n.type == "fingertip"}
    thumb = tips.pop("thumb")
    return float(np.mean([np.linalg.norm(thumb - p) for p in tips.values()]))


def rest(spec) -> np.ndarray:
    return np.clip(0.0, [r.lower for r in spec.joints], [r.upper for r in spec.joints])


@needs_assets()
@pytest.mark.parametrize("path", shipped_specs(), ids=lambda p: p.parent.name)
def test_thumb_opens_on_every_shipped_hand(path):
    spec = load_spec(path)
    q, note = deploy_start_pose(spec, None, str(asset_root()))
    assert note is None
    lo, hi = np.array([[r.lower, r.upper] for r in spec.joints]).T
    assert np.all(q >= lo) and np.all(q <= hi)
    thumb = {n.id for n in spec.nodes if n.finger == "thumb"}
    for i, r in enumerate(spec.joints):
        if r.node not in thumb:
            assert q[i] == rest(spec)[i], r.joint  # other fingers stay at the open rest pose
        elif r.primitive.value == "FLEX":
            assert q[i] == (hi[i] if r.sign < 0 else lo[i]), r.joint  # −FLEX limit
    before, after = spread(spec, rest(spec)), spread(spec, q)
    assert after >= before - 1e-6
    if spec.name in OPENS:
        assert after > before + 0.005, (spec.name, before, after)


def test_without_kinematics_only_flex_opens():
    spec = load_spec(resolve_spec("shadow"))  # the spec alone: no URDF needed
    q = thumb_open_pose(spec, None)
    thumb = {n.id for n in spec.nodes if n.finger == "thumb"}
    for i, r in enumerate(spec.joints):
        if r.node in thumb and r.primitive.value == "FLEX":
            assert q[i] == (r.upper if r.sign < 0 else r.lower), r.joint
        else:
            assert q[i] == rest(spec)[i], r.joint  # thumb ABD/ROT need forward kinematics: left at rest
    assert np.any(q != rest(spec))


@needs_assets()
def test_deploy_ramp_ends_at_the_thumb_open_pose(tmp_path):
    spec = load_spec(resolve_spec("leap"))
    expect, _ = deploy_start_pose(spec, None, str(asset_root()))
    log = tmp_path / "leap.jsonl"
    out = Console(width=200, record=True)
    contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=1, lift_steps=0, hold_s=0.0))
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
