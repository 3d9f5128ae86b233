"""Why does a hand never touch the object? The guided, thumb-opened scripted grasp (E0′ of docs/training.md: guidance
0.05, thumb_open 0.5, Markov layout, seed 0) on one object × 10 slots: per slot whether the hand touched the object,
the closest palm → surface distance and the guidance error at the end of the grasp phase, and which hand bodies
touch the table (the world body) then.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/trace_table_contacts.py HAND OBJECT [ROLL]"""
import sys

import mujoco
import numpy as np
from probe_common import LAYOUT

from dgz_cli.sim.evaluate import make_env, palm_object_distance
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import ControlContract, StartPose, WristGuidance
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec

if __name__ == "__main__":
    hand, obj, roll = sys.argv[1], sys.argv[2], (sys.argv[3] if len(sys.argv) > 3 else "narrow")
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05), start=StartPose(thumb_open=0.5))
    env = make_env([(load_spec(resolve_spec(hand)), o) for o in resolve_objects(obj)] * 10,
                   EnvConfig(contract=contract, roll=roll), seed=0)
    policy = ScriptedGrasp.for_env(env)
    obs = env.reset(0)
    policy.reset(None)
    closest = np.full(env.B, np.inf)
    for _ in range(contract.episode.grasp_steps):
        closest = np.minimum(closest, palm_object_distance(env)[0])
        obs, *_ = env.step(policy.act(obs))
    guide = np.linalg.norm(obs["global"][:, LAYOUT.global_col("guide")].astype(float) * LAYOUT.target_scale, axis=-1)
    for b, s in enumerate(env.slots):
        m, d = s.model, s.data
        table = sorted({mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.geom_bodyid[g]))
                        for c in d.contact[:d.ncon] for g in (c.geom1, c.geom2)
                        if m.geom_bodyid[c.geom1] == 0 or m.geom_bodyid[c.geom2] == 0} - {"world", "obj/object"})
        print(f"slot {b}: touched {bool(env.touched[b])}, closest palm-surface {closest[b]:.3f} m, "
              f"guidance error {guide[b]:.3f} m, hand bodies on the table: {', '.join(table) or 'none'}")
    env.close()
