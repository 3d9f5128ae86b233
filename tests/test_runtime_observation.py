"""The hardware observation builder against the training env, and the --object-points file format."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from dgz_cli.hw.arm import SimArm
from dgz_cli.hw.sim_hand import SimHand
from dgz_cli.runtime.kinematics import HandKinematics
from dgz_cli.runtime.observation import MAX_POINTS, HardwareObservation, load_object_points
from dgz_cli.runtime.types import StepInput
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scene import HAND_PREFIX
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec

TRI = load_spec(resolve_spec("dgz_tri"))
CFG = EnvConfig()


def env_state(obj_in_palm: np.ndarray):
    """Run the training env a few steps (fingers closing), move the object next to the palm, step once more;
    return its observation, every hand joint's value by name, and the object's cloud in the palm frame."""
    env = GraspEnv([(TRI, resolve_objects("box")[0])], CFG, seed=3, threads=1)
    env.reset()
    s = env.slots[0]
    d, idx = s.data, s.idx
    action = np.zeros((1, env.action_dim))
    action[0, 6::3], action[0, 7::3] = 1.0, 0.5  # +FLEX, +ABD on every node: a partly closed hand
    for _ in range(20):
        env.step(action)

    def palm():
        rot_link = d.xmat[idx.palm_body].reshape(3, 3)
        return rot_link @ idx.palm_axes, d.xpos[idx.palm_body] + rot_link @ idx.palm_center

    palm_rot, palm_pos = palm()
    d.qpos[idx.object_qadr:idx.object_qadr + 3] = palm_pos + palm_rot @ obj_in_palm
    d.qvel[idx.object_dadr:idx.object_dadr + 6] = 0.0
    obs, _, _, truncated, info = env.step(action * 0.0)
    assert not truncated[0] and not info["episode"]  # the observation belongs to this state, not a reset
    palm_rot, palm_pos = palm()
    obj_rot = d.xmat[idx.object_body].reshape(3, 3)
    cloud_palm = (d.xpos[idx.object_body] + idx.cloud @ obj_rot.T - palm_pos) @ palm_rot
    joints = {}
    for j in range(s.model.njnt):
        name = mujoco.mj_id2name(s.model, mujoco.mjtObj.mjOBJ_JOINT, j) or ""
        if name.startswith(HAND_PREFIX):
            joints[name[len(HAND_PREFIX):]] = float(d.qpos[s.model.jnt_qposadr[j]])
    env.close()
    return obs, joints, cloud_palm


def test_node_features_agree_with_the_training_env():
    obs, joints, cloud_palm = env_state(np.array([0.04, 0.01, 0.06]))
    n = len(TRI.nodes)
    q = np.array([joints[r.joint] for r in TRI.joints])
    assert np.ptp(q) > 0.1  # not the rest pose
    hand = SimHand(TRI, control_dt=0.05)
    with hand:  # the sim backend in the same state, read through the driver interface
        hand.enable()
        for name, value in joints.items():
            jid = mujoco.mj_name2id(hand.model, mujoco.mjtObj.mjOBJ_JOINT, name)
            hand.data.qpos[hand.model.jnt_qposadr[jid]] = value
        hand.data.ctrl[hand.acts] = q
        state = hand.read_state()
    assert np.max(np.abs(state.q - q)) < 2e-3
    builder = HardwareObservation(TRI, CFG.contract)
    builder.reset(TRI, {"object_points": cloud_palm, "rate_hz": 20.0})
    x = builder.build(StepInput(0, state, q, np.zeros(6 + 3 * n), np.zeros(6)))
    env_nodes, hw_nodes = obs["nodes"][0, :n], x["nodes"][0]
    assert np.abs(env_nodes[:, 0:3]).max() > 0.1 and np.linalg.norm(env_nodes[:, 0:3], axis=1).min() < 0.5
    np.testing.assert_allclose(hw_nodes[:, 0:3], env_nodes[:, 0:3], atol=5e-3)   # d (÷ 0.3 m): ≤ 1.5 mm
    np.testing.assert_allclose(hw_nodes[:, 3:6], env_nodes[:, 3:6], atol=1e-3)   # θ (÷ π)
    np.testing.assert_allclose(x["global"][0, 0:3], obs["global"][0, 0:3], atol=1e-3)  # Δp to the object centre
    np.testing.assert_array_equal(hw_nodes[:, 11:], env_nodes[:, 11:])  # finger and node-type one-hots
    for key in ("physical", "mask", "node_valid"):
        np.testing.assert_array_equal(x[key][0], obs[key][0, :n])
    np.testing.assert_array_equal(x["adjacency"][0], obs["adjacency"][0, :n, :n])
    assert np.all(hw_nodes[:, 9:11] == 0) and x["global"][0, 15] == 0  # no contact/force sensing, no lift flag


def test_joint_velocity_from_finite_differences():
    from dgz_cli.hw.driver import HandState

    builder = HardwareObservation(TRI, CFG.contract)
    builder.reset(TRI, {"object_points": np.array([[0.0, 0.0, 0.1]]), "rate_hz": 20.0})
    q0 = HandKinematics.for_spec(TRI).rest.copy()
    k = [r.joint for r in TRI.joints].index("index_mcp")
    q1 = q0.copy()
    q1[k] += 0.05
    builder.build(StepInput(0, HandState(q0, q0 * 0, "sim", 1.00), q0, np.zeros(1), np.zeros(6)))
    x = builder.build(StepInput(1, HandState(q1, q0 * 0, "sim", 1.05), q1, np.zeros(1), np.zeros(6)))
    node = TRI.node_index()[TRI.joints[k].node]
    assert x["nodes"][0, node, 6] == pytest.approx(TRI.joints[k].sign * 0.05 / 0.05 / 10.0, abs=1e-5)  # FLEX, ÷10
    x = builder.build(StepInput(2, None, q1, np.zeros(1), np.zeros(6)))  # a lost reading: last q, zero velocity
    assert np.all(x["nodes"][0, :, 6:9] == 0)


def test_wrist_velocity_from_the_commanded_palm_motion():
    kin = HandKinematics.for_spec(TRI)
    kin.pose(kin.rest)
    arm = SimArm(*kin.palm_frame())
    arm.enable()
    builder = HardwareObservation(TRI, CFG.contract, kin=kin)
    builder.reset(TRI, {"object_points": np.array([[0.0, 0.0, 0.1]]), "rate_hz": 20.0})
    s = StepInput(0, None, kin.rest, np.zeros(1), np.zeros(6), arm.palm_pose())
    x0 = builder.build(s)
    arm.command(np.array([0.004, 0.0, 0.006, 0.0, 0.0, 0.0]))  # palm frame: 4 mm along f, 6 mm along n
    x1 = builder.build(StepInput(1, None, kin.rest, np.zeros(1), np.zeros(6), arm.palm_pose()))
    np.testing.assert_allclose(x1["global"][0, 3:6], [0.08, 0.0, 0.12], atol=1e-6)  # m/s, palm frame
    np.testing.assert_allclose(x1["global"][0, 0:3] - x0["global"][0, 0:3], [-0.008, 0.0, -0.012], atol=1e-6)
    arm.command(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.01]))  # 0.01 rad about n
    x2 = builder.build(StepInput(2, None, kin.rest, np.zeros(1), np.zeros(6), arm.palm_pose()))
    np.testing.assert_allclose(x2["global"][0, 6:9], [0.0, 0.0, 0.2 / 5.0], atol=1e-5)  # ω ÷ 5 rad/s


def test_object_points_file_format(tmp_path):
    good = tmp_path / "pts.txt"
    good.write_text("0.01, 0.0, 0.08\n0.02 0.01 0.09\n")
    assert load_object_points(good).shape == (2, 3)
    big = tmp_path / "big.npy"
    np.save(big, np.random.default_rng(0).normal(0, 0.02, (3 * MAX_POINTS, 3)))
    assert len(load_object_points(big)) <= MAX_POINTS
    cases = {
        "missing.npy": (None, "no such point-cloud file"),
        "two.txt": ("1 2\n3 4\n", "expected K×3 points, got shape \\(2, 2\\)"),
        "words.txt": ("x y z\n", "cannot read points"),
        "nan.txt": ("0 0 nan\n", "1 non-finite values"),
        "mm.txt": ("10 0 80\n20 10 90\n", "centroid is .* m from the palm centre"),
        "obj.npy": (np.array([{"a": 1}], dtype=object), "cannot read points"),
        "str.npy": (np.array([["a", "b", "c"]]), "holds <U1 values, not numbers"),
    }
    for name, (content, message) in cases.items():
        path = tmp_path / name
        if isinstance(content, str):
            path.write_text(content)
        elif content is not None:
            np.save(path, content, allow_pickle=True)
        with pytest.raises(DgzError, match=message) as info:
            load_object_points(path)
        assert name in info.value.message and "\n" not in info.value.message and info.value.hint


def test_builtin_object_points_sit_in_front_of_the_palm(tmp_path, monkeypatch):
    pts = load_object_points("sphere")
    centre = pts.mean(0)
    assert pts.shape == (256, 3) and np.allclose(centre, [0, 0, 0.25], atol=0.01)
    r = np.linalg.norm(pts - [0, 0, 0.25], axis=1)  # on the sim's (triangulated) 35 mm sphere
    assert r.max() <= 0.035 + 1e-9 and r.min() > 0.033
    box = load_object_points("box")
    assert np.abs(box - [0, 0, 0.25]).max(0) == pytest.approx([0.03, 0.045, 0.05], abs=1e-9)
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "sphere", np.array([[0.0, 0.0, 0.1]]))  # a file of that name wins over the built-in
    assert load_object_points("sphere.npy").shape == (1, 3)
    with pytest.raises(DgzError, match="nor a built-in object"):
        load_object_points("cube")
