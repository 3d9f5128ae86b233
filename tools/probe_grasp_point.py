"""Where the wrist guidance aims, on the nine objects YCB-45 is lost on (issue 11, docs/training.md after E16): the
scripted grasp under E13's settings (guidance 0.05, clear roll, thumb half open; `dgz eval --policy scripted --roll
clear --thumb-open 0.5 --guidance 0.05`), 5 trials per object, with the guidance's grasp point — the point it steers
onto the object cloud's centroid — at the open hand's centroid of (a) every node (the contract's, `base`), (b) the
distal and fingertip nodes (`distal`), (c) the fingertip nodes (`tips`), all from the flat open hand in the palm
frame as `dgz_cli.runtime.observation.grasp_offset_of` measures it. Prints success and the failed episodes per
class of `dgz eval` (`dgz_cli.sim.evaluate.failure_class`).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_grasp_point.py HANDS [VARIANTS]"""
from probe_common import main, probe

from dgz_cli.rl.config import TrainConfig, env_config
from dgz_cli.spec.kinematics import HandKinematics

NINE = "032_knife,030_fork,031_spoon,040_large_marker,037_scissors,071_nine_hole_peg_test,035_power_drill," \
       "028_skillet_lid,048_hammer"
# name: the node types whose open-hand centroid is the grasp point (None: every node, the contract's)
VARIANTS = {"base": None, "distal": ("distal", "fingertip"), "tips": ("fingertip",)}


def run(spec, types):
    cfg = env_config(TrainConfig(guidance_gain=0.05, roll="clear", thumb_open=0.5))

    def aim(env):
        if types is not None:
            kin = HandKinematics.for_spec(spec)
            anchors = kin.anchors_palm(kin.rest)  # (N, 3) palm frame, the flat open hand
            env.grasp_offset[:] = anchors[[n.type in types for n in spec.nodes]].mean(0)

    return probe(spec, cfg.contract, None, slots=1, setup=aim, objects=NINE, trials=5,
                 env={k: getattr(cfg, k) for k in type(cfg).model_fields if k != "contract"})


if __name__ == "__main__":
    main(VARIANTS, run)
