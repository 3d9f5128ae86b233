"""Where the object sits in the hand when the scripted grasp starts to close, and where the fingers end up (issue 11,
docs/training.md after E16): the scripted grasp under E13's settings (`dgz eval --policy scripted --roll clear
--thumb-open 0.5 --guidance 0.05`, seed 0, the same episodes) on one hand and object. For each episode it prints,
at the closing onset and at the end of the grasp phase, the palm centre's height above the table, the object
centre and every node anchor in the palm frame (f, l, n: fingers' direction, lateral, palm normal; m) with their
heights, and the contact normal force per node at the end of the grasp phase.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/trace_grasp_onset.py HAND OBJECT [TRIALS]"""
import sys

import numpy as np

from dgz_cli.rl.config import TrainConfig, env_config
from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def show(label, env, st):
    rot, palm = st["palm_rot"][0], st["palm_pos"][0]
    in_palm = lambda x: (x - palm) @ rot  # noqa: E731
    print(f"  {label}: step {env.t[0]}, palm height {palm[2]:.3f}, object (f, l, n) {in_palm(st['obj_pos'][0])} "
          f"height {st['obj_pos'][0, 2]:.3f}")
    for i, node in enumerate(env.slots[0].spec.nodes):
        print(f"    {node.id:16s} {in_palm(st['nodes'][0, i])} height {st['nodes'][0, i, 2]:.3f}")


def main(hand: str, obj: str, trials: int = 1) -> None:
    np.set_printoptions(precision=3, suppress=True)
    cfg = env_config(TrainConfig(guidance_gain=0.05, roll="clear", thumb_open=0.5))
    env = make_env([(load_spec(resolve_spec(hand)), resolve_objects(obj)[0])], cfg)
    grasp = ScriptedGrasp.for_env(env)
    obs, closing, episode = env.reset(0), False, 0
    grasp.reset(None)
    while episode < trials:
        action = grasp.act(obs)
        st = env.state()
        if grasp.closing[0] and not closing:
            print(f"episode {episode}")
            show("closing onset", env, st)
        closing = bool(grasp.closing[0])
        if env.t[0] == cfg.contract.episode.grasp_steps - 1:
            show("end of the grasp phase", env, st)
            print(f"    contact force per node (N): {st['force'][0]}")
        obs, _, _, _, info = env.step(action)
        if info["episode"]:
            rec = info["episode"][0]
            print(f"  success {rec['success']}, max rise {rec['max_rise']:.3f} m, max push {rec['max_push']:.3f} m")
            grasp.reset(None)
            closing, episode = False, episode + 1
    env.close()


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(f"usage: {sys.argv[0]} HAND OBJECT [TRIALS]")
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 1)
