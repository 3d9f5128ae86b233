"""Is the object at rest when an episode starts? After each slot's reset (the object dropped in a random orientation
and settled for the env's ``settle_s``), the hand is moved out of the way and the object is left alone for SECONDS
more; per object, the horizontal drift of its body origin (cm) from the episode's first frame at 0.5 s, 1 s and
SECONDS. A held first-frame cloud (the hardware view, `dgz_cli.spec.hardware_view`) is off by that much before the
hand touches anything.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_settle_drift.py HAND OBJECTS SLOTS SETTLE_S SECONDS`
(OBJECTS as `dgz eval --objects`; SETTLE_S overrides the env's settle time, e.g. its default 0.3)"""
import json
import sys

import mujoco
import numpy as np

from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.slot import PARKED_WRIST_XYZ
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec


def main() -> None:
    if len(sys.argv) != 6:
        sys.exit(__doc__.splitlines()[-2])
    spec = load_spec(resolve_spec(sys.argv[1]))
    objects = resolve_objects(sys.argv[2])
    slots, settle_s, seconds = int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
    cfg = EnvConfig(settle_s=settle_s)
    env = make_env([(spec, o) for o in objects] * slots, cfg, seed=0)
    env.reset(0)
    dt = cfg.contract.episode.physics_dt
    times = sorted({0.5, 1.0, seconds})
    drift: dict[str, list[list[float]]] = {o.name: [] for o in objects}
    for b, slot in enumerate(env.slots):
        m, d, idx = slot.model, slot.data, slot.idx
        start = d.xpos[idx.object_body][:2].copy()
        d.qpos[idx.wrist_qadr[:3]] = PARKED_WRIST_XYZ  # the hand out of the way, as while the object settled
        d.ctrl[:3] = d.qpos[idx.wrist_qadr[:3]]
        d.qvel[:] = 0.0
        row, now = [], 0.0
        for t in times:
            mujoco.mj_step(m, d, nstep=max(1, int(round((t - now) / dt))))
            now = t
            row.append(round(100 * float(np.linalg.norm(d.xpos[idx.object_body][:2] - start)), 2))
        drift[objects[b % len(objects)].name].append(row)
    last = np.array([r[-1] for rows in drift.values() for r in rows])
    for name, rows in drift.items():
        print(name, " | ".join(" ".join(f"{t:g}s {x:.1f}" for t, x in zip(times, r)) for r in rows), flush=True)
    print(json.dumps(dict(settle_s=settle_s, seconds=seconds, starts=len(last),
                          moved_over_1cm=int((last > 1.0).sum()), moved_over_3cm=int((last > 3.0).sum()),
                          mean_cm=round(float(last.mean()), 2), max_cm=round(float(last.max()), 2))))


if __name__ == "__main__":
    main()
