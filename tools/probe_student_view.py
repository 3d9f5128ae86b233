"""Where does a hardware view cost success? A checkpoint (a distilled student or a privileged teacher) evaluated in
its own env on eval's start states (`dgz eval`'s loop and summary) under parts of the hardware view
(`dgz_cli.spec.hardware_view`), per hand: the success rate and the failure classes.

Views (comma-separated VIEWS; default all):
* ``none``: the simulator's observation (`dgz eval --no-perturb` for a student);
* ``noise``: joint readings with 0.01 rad noise, the object live;
* ``held``: the object cloud held from the first frame (node → surface vectors, target and guidance, zero
  object velocity), no joint noise;
* ``hw``: both (`dgz distill`'s default view; `dgz eval` of a student);
* ``held_target``: only the grasp target (and the guidance that steers to it) held; the node → surface vectors
  and object velocities live;
* ``held_surface``: only the node → surface vectors held and the object velocities 0; the target live;
* ``hw_grasp``: ``hw`` during the grasp phase only; from the lift on, the object blocks live (the estimate a
  runtime has if it assumes that a grasped object moves with the palm).

A teacher keeps its privileged contact and force inputs under every view. SETTLE_S, if given, overrides the
env's ``settle_s`` (how long the object settles before the first frame; `tools/probe_settle_drift.py`).

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_student_view.py CHECKPOINT HANDS OBJECTS TRIALS [VIEWS [SETTLE_S]]`"""
import json
import sys

import numpy as np
from probe_common import checkpoint_summary

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.spec.hardware_view import HARDWARE, HardwareView

HELD = HardwareView(held_cloud=True)
OBJECT_NODE, OBJECT_GLOBAL = ("d",), ("target", "guide", "v_obj", "w_obj")
# view name → (HardwareView, observation blocks put back to the live ones after the view: node, global;
#              the first control step from which they are put back)
VIEWS = {
    "none": (None, (), (), 0),
    "noise": (HardwareView(joint_noise=HARDWARE.joint_noise), (), (), 0),
    "held": (HELD, (), (), 0),
    "hw": (HARDWARE, (), (), 0),
    "held_target": (HELD, OBJECT_NODE, ("v_obj", "w_obj"), 0),
    "held_surface": (HELD, (), ("target", "guide"), 0),
    "hw_grasp": (HARDWARE, OBJECT_NODE, OBJECT_GLOBAL, None),
}


def restore_live(env, node_blocks: tuple[str, ...], global_blocks: tuple[str, ...], from_step: int = 0) -> None:
    """Make ``env`` (a HardwareViewEnv) put the named blocks of its perturbed observation back to the live ones
    in the slots at control step ``from_step`` or later (the guidance and the closing prior read the observation,
    so a live target steers them to the live object)."""
    lay = env.cfg.contract.observation
    node_blocks = tuple(k for k in node_blocks if lay.has(k))
    global_blocks = tuple(k for k in global_blocks if lay.has(k))
    perturb = env._perturb

    def partial(obs: dict, rows):
        out = perturb(obs, rows)
        nodes, glob = out["nodes"].copy(), out["global"].copy()
        rows = np.asarray(rows)[env.t[rows] >= from_step]
        for k in node_blocks:
            nodes[rows, :, lay.node_col(k)] = obs["nodes"][rows][:, :, lay.node_col(k)]
        for k in global_blocks:
            glob[rows, lay.global_col(k)] = obs["global"][rows][:, lay.global_col(k)]
        return {**out, "nodes": nodes, "global": glob}

    env._perturb = partial


def main() -> None:
    if len(sys.argv) not in (5, 6, 7):
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    objects, trials = sys.argv[3], int(sys.argv[4])
    names = sys.argv[5].split(",") if len(sys.argv) >= 6 else list(VIEWS)
    cfg = policy.meta.env
    if len(sys.argv) == 7:
        cfg = cfg.model_copy(update=dict(settle_s=float(sys.argv[6])))
    unknown = sorted(set(names) - set(VIEWS))
    if unknown:
        sys.exit(f"unknown view(s) {unknown}; choose from {','.join(VIEWS)}")
    out: dict = {}
    for hand in sys.argv[2].split(","):
        for name in names:
            view, node_live, global_live, from_step = VIEWS[name]

            def make_policy(env, node_live=node_live, global_live=global_live, from_step=from_step):
                if node_live or global_live:
                    grasp_steps = env.cfg.contract.episode.grasp_steps
                    restore_live(env, node_live, global_live, grasp_steps if from_step is None else from_step)
                return policy

            summary = checkpoint_summary(policy, hand, objects, trials, make_policy, cfg, view)
            out.setdefault(hand, {})[name] = dict(success=round(summary["success_rate"], 3),
                                                  failures=summary["failures"])
            print(hand, name, json.dumps(out[hand][name]), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
