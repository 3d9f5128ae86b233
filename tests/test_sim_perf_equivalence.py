"""The env's fast paths (batched state gather, batched contact forces, precomputed observation terms)
against straightforward per-slot reference code, and a recorded-rollout equivalence check across
code versions.

* ``test_gather_matches_per_slot_reference`` (threads 1 and 2): after every step of noisy scripted
  grasps on a mixed batch, what the observation is built from (node anchor positions, palm frame,
  object pose and velocities, joint values, per-node contact normal forces, zero padding) equals what a
  plain per-slot loop computes from ``MjData`` with ``data.xpos`` / ``data.xmat`` and
  ``mujoco.mj_contactForce``; so does the per-slot fallback ``Slot.contacts``.
* ``test_pyramidal_cone_slots_mixed_into_a_batch``: the same with some slots on pyramidal cones (they
  compute their own forces) mixed with batched elliptic ones.
* Across code versions (a script, not a test: it needs a recording from the older code):
  ``python tests/test_sim_perf_equivalence.py --record ref.npz`` with the old code, then ``--check ref.npz``
  with the new: observations, rewards, reward terms, dones, instabilities and episode outcomes of three
  rollouts (default protocol; short episodes with resets, successes and a forced NaN; joint action mode
  single-threaded) must be identical (floats to 1e-12, the rest exactly).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import asset_root, shipped_specs  # noqa: E402

from dgz_cli.spec.envconfig import EnvConfig  # noqa: E402
from dgz_cli.spec.contract import ActionLayout, ControlContract, EpisodeProtocol  # noqa: E402
from dgz_cli.sim.env import GraspEnv  # noqa: E402
from dgz_cli.sim.objects import resolve_objects  # noqa: E402
from dgz_cli.sim.scripted import ScriptedGrasp  # noqa: E402
from dgz_cli.spec.io import load_spec  # noqa: E402

OBJECTS = resolve_objects("sphere,box,cylinder,capsule")
EPISODE_KEYS = ("success", "unstable", "return_", "steps", "max_rise", "r_dis", "r_contact", "r_force", "r_reg",
                "r_pen")


def _spec(stem: str):
    return load_spec(next(p for p in shipped_specs() if p.parent.name == stem))


def _hands() -> list[str]:
    """dgz_tri (built-in URDF) always; vendor hands (capsule and mesh ones) when the assets are there."""
    return ["dgz_tri"] + (["leap", "allegro", "inspire", "barrett"] if asset_root() is not None else [])


def _env(cfg: EnvConfig, threads: int, seed: int, n: int = 8) -> GraspEnv:
    specs = [_spec(h) for h in _hands()]
    pairs = [(specs[i % len(specs)], OBJECTS[(i // len(specs) + i) % len(OBJECTS)]) for i in range(n)]
    root = str(asset_root()) if asset_root() is not None else None
    return GraspEnv(pairs, cfg, seed=seed, asset_root=root, threads=threads)


# ------------------------------------------------------------------ recorded rollouts
CASES = {
    # name: (config, threads, seed, steps, step at which slot 1 gets NaN velocities or None)
    "default": (EnvConfig(), 2, 3, 40, None),
    # short episodes: several resets, successes (a low success bar) and a forced instability
    "short": (EnvConfig(contract=ControlContract(episode=EpisodeProtocol(grasp_steps=30, lift_steps=5, hold_s=0.25, success_fraction=0.0))), 2, 4, 60, 45),
    "joint_serial": (EnvConfig(contract=ControlContract(action=ActionLayout(mode="joint"))), 1, 5, 20, None),
}


def _actions(env: GraspEnv, scripted: ScriptedGrasp, obs: dict, rng: np.random.Generator) -> np.ndarray:
    """The scripted grasp (approach, close: hand–object contacts within ~30 steps) plus noise."""
    return np.clip(scripted.act(obs) + rng.uniform(-0.4, 0.4, (env.B, env.action_dim)), -1.0, 1.0)


def rollout(name: str) -> dict[str, np.ndarray]:
    cfg, threads, seed, steps, poison = CASES[name]
    env = _env(cfg, threads, seed)
    rng = np.random.default_rng(11)
    scripted = ScriptedGrasp.for_env(env)
    obs = env.reset()
    rec: dict[str, list] = {k: [] for k in ("nodes", "global", "reward", "terminated", "truncated", "success",
                                            "unstable", "episode")}
    rec["terms"] = []
    rec["nodes"].append(obs["nodes"].copy())
    rec["global"].append(obs["global"].copy())
    static = {k: obs[k].copy() for k in ("adjacency", "physical", "mask", "node_valid")}
    for t in range(steps):
        if poison is not None and t == poison:
            env.slots[1].data.qvel[:] = np.nan
        obs, reward, term, trunc, info = env.step(_actions(env, scripted, obs, rng))
        scripted.reset(term | trunc)
        rec["nodes"].append(obs["nodes"].copy())
        rec["global"].append(obs["global"].copy())
        rec["reward"].append(reward.copy())
        rec["terminated"].append(term.copy())
        rec["truncated"].append(trunc.copy())
        rec["success"].append(info["success"].copy())
        rec["unstable"].append(info["unstable"].copy())
        rec["terms"].append(np.stack([info["reward_terms"][k] for k in ("dis", "contact", "force", "reg", "pen")]))
        for b, ep in sorted(info["episode"].items()):
            rec["episode"].append([t, b] + [float(ep[k]) for k in EPISODE_KEYS])
    out = {k: np.asarray(v, dtype=float if k == "episode" else None) for k, v in rec.items()}
    out["episode"] = out["episode"].reshape(-1, 2 + len(EPISODE_KEYS))
    out.update(static)
    out["instabilities"] = np.array(env.instabilities)
    env.close()
    return out


def record(path: str) -> None:
    arrays = {f"{name}/{k}": v for name in CASES for k, v in rollout(name).items()}
    arrays["hands"] = np.array(_hands())
    np.savez(path, **arrays)


def check(path: str) -> None:
    """Replay the cases and compare with a reference recorded by an older version of the code."""
    ref = np.load(path)
    if list(ref["hands"]) != _hands():
        sys.exit(f"{path} was recorded with hands {list(ref['hands'])}, this run has {_hands()}: set DGZ_ASSET_ROOT alike")
    for name in CASES:
        got = rollout(name)
        for k, v in got.items():
            want = ref[f"{name}/{k}"]
            assert v.shape == want.shape, (name, k)
            if v.dtype.kind == "f":
                np.testing.assert_allclose(v, want, rtol=0, atol=1e-12, err_msg=f"{name}/{k}")
            else:
                assert np.array_equal(v, want), (name, k)
        if name == "short":
            assert got["instabilities"] >= 1 and got["episode"].shape[0] > 8 and got["episode"][:, 2].any()
        print(f"{name}: identical")


# ------------------------------------------------------------------ vectorized pieces vs. a per-slot loop
def _reference_state(env: GraspEnv, b: int) -> dict[str, np.ndarray]:
    """What the observation is built from, computed for slot ``b`` alone with plain MuJoCo calls."""
    import mujoco

    s = env.slots[b]
    m, d, idx = s.model, s.data, s.idx
    n = len(s.spec.nodes)
    nodes = np.array([d.xpos[idx.node_body[i]] + d.xmat[idx.node_body[i]].reshape(3, 3) @ idx.node_point[i]
                      for i in range(n)])
    palm_rot = d.xmat[idx.palm_body].reshape(3, 3)
    force = np.zeros(n)
    wrench = np.zeros(6)
    for k in range(d.ncon):
        c = d.contact[k]
        g1, g2 = c.geom[0], c.geom[1]
        b1, b2 = m.geom_bodyid[g1], m.geom_bodyid[g2]
        if b1 == idx.object_body and idx.geom_node[g2] >= 0:
            node = idx.geom_node[g2]
        elif b2 == idx.object_body and idx.geom_node[g1] >= 0:
            node = idx.geom_node[g1]
        else:
            continue
        if c.efc_address < 0:  # excluded / inactive contact: no force
            continue
        mujoco.mj_contactForce(m, d, k, wrench)
        force[node] += wrench[0]  # normal component in the contact frame
    return dict(
        nodes=nodes,
        palm_rot=palm_rot @ idx.palm_axes,
        palm_pos=d.xpos[idx.palm_body] + palm_rot @ idx.palm_center,
        obj_pos=d.xpos[idx.object_body].copy(),
        obj_rot=d.xmat[idx.object_body].reshape(3, 3).copy(),
        obj_vel=d.qvel[idx.object_dadr:idx.object_dadr + 6].copy(),
        q=d.qpos[idx.hand_qadr].copy(),
        qd=d.qvel[idx.hand_dadr].copy(),
        wq=d.qpos[idx.wrist_qadr].copy(),
        force=force,
    )


def _batch_state(env: GraspEnv, b: int) -> dict[str, np.ndarray]:
    """The same quantities as the env sees them in its batch buffers (through ``GraspEnv.state``)."""
    st = env.state()
    n, nj = len(env.slots[b].spec.nodes), env.slots[b].n_joints
    return dict(nodes=st["nodes"][b, :n], palm_rot=st["palm_rot"][b], palm_pos=st["palm_pos"][b],
                obj_pos=st["obj_pos"][b], obj_rot=st["obj_rot"][b], obj_vel=st["obj_vel"][b],
                q=st["q"][b, :nj], qd=st["qd"][b, :nj], wq=st["wq"][b], force=st["force"][b, :n])


def _check_against_reference(env: GraspEnv, steps: int = 40) -> int:
    """Scripted grasps with noise; after every step each slot's batched state, and its per-slot
    ``Slot.contacts`` fallback, must equal the per-slot reference. Returns the number of (slot, step)
    pairs with some hand–object force, so callers can insist the force path was exercised."""
    obs = env.reset()
    rng = np.random.default_rng(0)
    scripted = ScriptedGrasp.for_env(env)
    touched = 0
    for t in range(steps):
        obs, *_ = env.step(_actions(env, scripted, obs, rng))
        st = env.state()
        for b, s in enumerate(env.slots):
            want, got = _reference_state(env, b), _batch_state(env, b)
            for k in want:
                np.testing.assert_allclose(got[k], want[k], rtol=0, atol=1e-9, err_msg=f"slot {b} {k} step {t}")
            assert not st["force"][b, len(s.spec.nodes):].any()  # padded nodes
            own = np.full(len(s.spec.nodes), np.nan)
            s.contacts(own)
            np.testing.assert_allclose(own, want["force"], rtol=0, atol=1e-9, err_msg=f"Slot.contacts {b} step {t}")
            touched += int((want["force"] > 0).any())
    return touched


@pytest.mark.parametrize("threads", [1, 2])
def test_gather_matches_per_slot_reference(threads):
    env = _env(EnvConfig(), threads, seed=2)
    touched = _check_against_reference(env)
    env.close()
    assert touched > 10, "too few hand–object contact forces: the force check compared mostly zeros"


def test_pyramidal_cone_slots_mixed_into_a_batch():
    """Slots whose model uses pyramidal friction cones compute their own forces (sum of the facets);
    the batched path must leave their rows alone and still handle the elliptic slots."""
    import mujoco

    env = _env(EnvConfig(), threads=2, seed=2)
    pyramidal = env.slots[0].model
    pyramidal.opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    for s in env.slots:
        if s.model is pyramidal:
            s._elliptic = s.stash_contacts = False
    assert any(s.stash_contacts for s in env.slots) and not env.slots[0].stash_contacts
    touched = _check_against_reference(env)
    env.close()
    assert touched > 10


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] in ("--record", "--check"):
        (record if sys.argv[1] == "--record" else check)(sys.argv[2])
        print("done:", sys.argv[1][2:], sys.argv[2])
    else:
        sys.exit("usage: python tests/test_sim_perf_equivalence.py --record FILE.npz | --check FILE.npz")
