"""Do the objects stay upright? Each object is dropped in its model's frame with a random yaw
(``object_orientation: upright``, GraspXL's and RobustDexGrasp's placement) and settles for SETTLE_S; per object,
the tilt (degrees) of its model z axis from the vertical at the episode's first frame, over SLOTS starts.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_upright.py HAND OBJECTS SLOTS SETTLE_S`
(OBJECTS as `dgz eval --objects`, e.g. ycb45)"""
import json
import sys

import numpy as np

from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(__doc__.splitlines()[-2])
    spec = load_spec(resolve_spec(sys.argv[1]))
    objects = resolve_objects(sys.argv[2])
    slots, settle_s = int(sys.argv[3]), float(sys.argv[4])
    env = make_env([(spec, o) for o in objects] * slots, EnvConfig(object_orientation="upright", settle_s=settle_s),
                   seed=0)
    env.reset(0)
    cos = np.clip(env.state()["obj_rot"][:, 2, 2], -1.0, 1.0)
    tilt = np.degrees(np.arccos(cos)).reshape(slots, len(objects))
    worst = {o.name: round(float(tilt[:, i].max()), 1) for i, o in enumerate(objects)}
    print(json.dumps(dict(settle_s=settle_s, slots=slots, max_tilt_deg=worst,
                          within_3_deg=sum(v <= 3.0 for v in worst.values()),
                          within_10_deg=sum(v <= 10.0 for v in worst.values()), objects=len(objects))))


if __name__ == "__main__":
    main()
