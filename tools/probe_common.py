"""What the probes in tools/ share: the ladder's 10 objects, E6's Markov layout, episodes on (object, slot) pairs
through `dgz eval`'s own loop and summary (`dgz_cli.sim.evaluate.run_episodes`, `summarize`), either a fixed
action rule on a zero residual or the scripted grasp, or a checkpoint in its own env, and the per-hand command line
`HANDS [VARIANTS]`."""
import json
import sys
from collections.abc import Callable

import numpy as np

from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.evaluate import run_episodes, summarize
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ControlContract, ObservationLayout
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.kinematics import HandKinematics

OBJS = ("004_sugar_box,005_tomato_soup_can,006_mustard_bottle,011_banana,013_apple,017_orange,025_mug,"
        "055_baseball,061_foam_brick,077_rubiks_cube")
LAYOUT = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)
# the nine objects YCB-45 is lost on (docs/training.md, after E16)
NINE = ("032_knife,030_fork,031_spoon,040_large_marker,037_scissors,071_nine_hole_peg_test,035_power_drill,"
        "028_skillet_lid,048_hammer")
# four round or boxy objects every hand lifts often: the controls beside the lost objects
CONTROL = "005_tomato_soup_can,013_apple,006_mustard_bottle,011_banana"


def open_hand_tips(spec, q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(3,), (3,) m: the thumb's fingertip and the mean of the other fingertips, palm frame (where the guidance's
    grasp point is measured), at joint positions ``q`` (L,) (None: the flat open hand, the spec's rest pose)."""
    kin = HandKinematics.for_spec(spec)
    anchors = kin.anchors_palm(kin.rest if q is None else q)  # (N, 3)
    tip = [n.type == "fingertip" for n in spec.nodes]
    thumb = anchors[[t and n.finger == "thumb" for t, n in zip(tip, spec.nodes)]].mean(0)
    return thumb, anchors[[t and n.finger != "thumb" for t, n in zip(tip, spec.nodes)]].mean(0)


def e13_scripted() -> tuple[EnvConfig, dict]:
    """The env of `dgz eval --policy scripted --roll clear --thumb-open 0.5 --guidance 0.05` (E13's settings): its
    EnvConfig, and its fields other than the contract as :func:`probe`'s ``env``."""
    from dgz_cli.rl.config import TrainConfig, env_config

    cfg = env_config(TrainConfig(guidance_gain=0.05, roll="clear", thumb_open=0.5))
    return cfg, {k: getattr(cfg, k) for k in type(cfg).model_fields if k != "contract"}


def probe(spec, contract: ControlContract, action: Callable[[GraspEnv], np.ndarray] | None, slots: int = 3,
          setup: Callable[[GraspEnv], None] | None = None, objects: str = OBJS, trials: int = 1,
          env: dict | None = None, make_policy: Callable[[GraspEnv], object] | None = None) -> dict:
    """``trials`` episodes on each of ``objects`` × ``slots`` for HandSpec ``spec`` under ``contract`` (narrow roll,
    seed 0; ``env``: other EnvConfig fields). Each step the action is ``action(env)`` (B, action_dim), or with
    ``action`` None the scripted grasp's (`dgz eval --policy scripted`), or ``make_policy(env)``'s when given;
    ``setup(env)`` may patch the env before its reset.

    Returns the success rate and the count of failed episodes per failure class of `dgz eval`."""
    class Probe:
        def __init__(self, env: GraspEnv) -> None:
            self.env = env

        def reset(self, mask) -> None:
            pass

        def act(self, obs) -> np.ndarray:
            return action(self.env)

    def policy_for(env: GraspEnv):
        if setup is not None:
            setup(env)
        if make_policy is not None:
            return make_policy(env)
        return Probe(env) if action is not None else ScriptedGrasp.for_env(env)

    pairs = [(spec, o) for o in resolve_objects(objects)] * slots
    cfg = EnvConfig(contract=contract, **({"roll": "narrow"} | (env or {})))
    records = run_episodes(pairs, policy_for, trials=trials, cfg=cfg)
    (hand,) = summarize(records, contract.episode.lift_height, contract.episode.success_fraction).values()
    return {"success": round(hand["success_rate"], 3), **hand["failures"]}


def checkpoint_summary(policy, hand: str, objects: str, trials: int,
                       make_policy: Callable[[GraspEnv], object] | None = None, cfg: EnvConfig | None = None,
                       view=None) -> dict:
    """`dgz eval`'s summary of one hand (success_rate, failures, objects, ...) for ``trials`` episodes on each of
    ``objects``, in the env the LoadedPolicy ``policy`` records (eval's protocol and start states) or ``cfg``,
    under the HardwareView ``view`` (None: none), acting with ``make_policy(env)`` (default: the policy itself)."""
    spec = load_spec(resolve_spec(hand))
    records = run_episodes([(spec, o) for o in resolve_objects(objects)], make_policy or (lambda env: policy),
                           trials, cfg or policy.meta.env, view=view)
    (summary,) = summarize(records).values()
    return summary


def zero(env: GraspEnv) -> np.ndarray:
    """A zero residual (B, action_dim): the contract's closing prior, if on, acts alone."""
    return np.zeros((env.B, env.action_dim))


def main(variants: dict, run: Callable, default_hands: str | None = None) -> None:
    """`python tools/probe_X.py HANDS [VARIANTS]`: print `hand variant {success, failures...}` per pair as it
    finishes, then all of them as one JSON line {hand: {variant: result}}."""
    args = sys.argv[1:] or ([default_hands] if default_hands else [])
    if not args:
        sys.exit(f"usage: {sys.argv[0]} HANDS [VARIANTS]  (VARIANTS: {','.join(variants)})")
    names = args[1].split(",") if len(args) > 1 else list(variants)
    out: dict = {}
    for hand in args[0].split(","):
        spec = load_spec(resolve_spec(hand))
        for name in names:
            out.setdefault(hand, {})[name] = run(spec, variants[name])
            print(hand, name, out[hand][name], flush=True)
    print(json.dumps(out))


def main_grouped(variants: dict, run: Callable, groups: dict[str, str], default_slots: int) -> None:
    """`python tools/probe_X.py HANDS [VARIANTS] [SLOTS]`: ``run(spec, variant, objects, slots)`` for every hand,
    variant and object group (name → comma-separated objects); print `hand variant group {success, failures...}`
    as each finishes, then all of them as one JSON line {hand: {variant: {group: result}}}."""
    hands = sys.argv[1].split(",")
    names = sys.argv[2].split(",") if len(sys.argv) > 2 and sys.argv[2] else list(variants)
    slots = int(sys.argv[3]) if len(sys.argv) > 3 else default_slots
    out: dict = {}
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for name in names:
            for group, objs in groups.items():
                r = run(spec, variants[name], objs, slots)
                out.setdefault(hand, {}).setdefault(name, {})[group] = r
                print(hand, name, group, r, flush=True)
    print(json.dumps(out))
