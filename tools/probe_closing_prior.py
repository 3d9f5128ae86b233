"""Measure the closing prior alone (zero residual) against the guided scripted grasp on LEAP and Allegro
(docs/training.md, lever 6). Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_closing_prior.py"""

import numpy as np, sys
from dgz_cli.spec.contract import *
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec
objs=resolve_objects("025_mug,011_banana,004_sugar_box,013_apple,077_rubiks_cube")
L=ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)
def run(spec, c, scripted=False):
    env=GraspEnv([(spec,o) for o in objs]*2, EnvConfig(contract=c, roll="narrow"), threads=2)
    obs=env.reset(0); succ=[]; pol=ScriptedGrasp(env.N, env.grasp_offset, c) if scripted else None
    if pol: pol.reset(None)
    for t in range(190*2):
        a = pol.act(obs) if pol else np.zeros((env.B, env.action_dim))
        obs,r,te,tr,info=env.step(a)
        succ += [e["success"] for e in info["episode"].values()]
        if pol and info["episode"]:
            m=np.zeros(env.B,bool); m[list(info["episode"])]=True; pol.reset(m)
    env.close(); return round(float(np.mean(succ)),2)
g=WristGuidance(gain=0.05)
for hand in ("leap","allegro"):
    spec=load_spec(resolve_spec(hand))
    print(hand, "scripted+guid", run(spec, ControlContract(observation=L, guidance=g), True), flush=True)
    for cs, gap in ((50,0.03),(80,0.03),(80,0.05)):
        print(hand, "prior", cs, gap, run(spec, ControlContract(observation=L, guidance=g, prior=ClosingPrior(enabled=True, close_step=cs, close_gap=gap))), flush=True)
