"""Where the wrist guidance aims, on the nine objects YCB-45 is lost on (issue 11, docs/training.md after E16): the
scripted grasp under E13's settings (guidance 0.05, clear roll, thumb half open; `dgz eval --policy scripted --roll
clear --thumb-open 0.5 --guidance 0.05`), 5 trials per object, with the guidance's grasp point — the point it steers
onto the object cloud's centroid — at the open hand's centroid of (a) every node (the contract's, `base`), (b) the
distal and fingertip nodes (`distal`), (c) the fingertip nodes (`tips`), (d) the thumb–finger opposition centre,
halfway between the thumb's fingertip and the mean of the other fingertips (`opposition`), all from the flat open
hand in the palm frame as `dgz_cli.runtime.observation.grasp_offset_of` measures it. A third argument `ladder` takes
the ladder's 10 objects instead of the nine. Prints success and the failed episodes per
class of `dgz eval` (`dgz_cli.sim.evaluate.failure_class`).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_grasp_point.py HANDS [VARIANTS] [nine|ladder]"""
import sys

from probe_common import NINE, OBJS, e13_scripted, main, open_hand_tips, probe

from dgz_cli.spec.kinematics import HandKinematics

# name: the node types whose open-hand centroid is the grasp point (None: every node, the contract's)
VARIANTS = {"base": None, "distal": ("distal", "fingertip"), "tips": ("fingertip",), "opposition": "opposition"}


def run(spec, types):
    cfg, fields = e13_scripted()

    def aim(env):
        if types == "opposition":
            env.grasp_offset[:] = sum(open_hand_tips(spec)) / 2
        elif types is not None:
            kin = HandKinematics.for_spec(spec)
            anchors = kin.anchors_palm(kin.rest)  # (N, 3) palm frame, the flat open hand
            env.grasp_offset[:] = anchors[[n.type in types for n in spec.nodes]].mean(0)

    objects = OBJS if sys.argv[3:4] == ["ladder"] else NINE
    return probe(spec, cfg.contract, None, slots=1, setup=aim, objects=objects, trials=5, env=fields)


if __name__ == "__main__":
    main(VARIANTS, run)
