"""What the hand holds when the lift starts, by how the episode ends (issue 11, after E55: *not lifted* is the largest
failure class on every hand). A checkpoint runs the eval protocol (`dgz eval`'s episodes: its own env, seed 0,
``--settle`` as given) on HANDS × OBJECTS × TRIALS; at the first observation of the lift (control step
``grasp_steps``) it reads, per episode, the observed contact flag and normal force of every valid node: how many
nodes touch, which fingers (thumb, other fingers, the palm's nodes), whether the thumb opposes another finger, and
the summed normal force (each node's observation is clipped at 5 × force_scale); and, per quantity, the most it
reaches at any step of the lift (a hand whose fingers are still closing when the lift starts grips later). Per hand
and outcome (success and the failure classes of ``dgz eval``) it prints the episode count and the means, and one
line for all hands.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_lift_start_contacts.py CHECKPOINT HANDS OBJECTS
TRIALS [SETTLE_S]` (HANDS and OBJECTS as `dgz eval --hand/--objects` take them)."""
import sys
from collections import defaultdict

import numpy as np

from dgz_cli.cli.hand_refs import hand_specs
from dgz_cli.rl.checkpoint import LoadedPolicy, resolve_checkpoint
from dgz_cli.sim.evaluate import FAILURE_CLASSES, failure_class, run_episodes
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.models import FINGER_CLASSES

THUMB, PALM = FINGER_CLASSES.index("thumb"), FINGER_CLASSES.index("wrist")
OUTCOMES = ("success",) + FAILURE_CLASSES


class Recorder:
    """Acts as the loaded policy and keeps, per (slot, episode of that slot), the contact summary of the
    observation at control step ``grasp_steps`` and, under ``lift_*`` keys, the most of each over the lift's steps."""

    def __init__(self, env, loaded: LoadedPolicy):
        self.env, self.loaded = env, loaded
        layout = env.cfg.contract.observation
        self.contact, self.force = layout.node_col("contact"), layout.node_col("force")
        self.finger = layout.node_col("finger")
        self.force_scale = layout.force_scale
        self.grasp_steps = env.cfg.contract.episode.grasp_steps
        self.lift_steps = env.cfg.contract.episode.lift_steps
        self.episode = np.zeros(env.B, dtype=np.int64)
        self.at_lift: dict[tuple[int, int], dict] = {}

    def reset(self, mask) -> None:
        self.loaded.reset(mask)
        if mask is not None:
            self.episode[np.asarray(mask)] += 1

    def act(self, obs):
        lifting = (self.env.t >= self.grasp_steps) & (self.env.t < self.grasp_steps + self.lift_steps)
        for b in np.flatnonzero(lifting):
            now = self.summary(obs, b)
            key = (int(b), int(self.episode[b]))
            if self.env.t[b] == self.grasp_steps:
                self.at_lift[key] = now | {f"lift_{k}": v for k, v in now.items()}
            elif key in self.at_lift:  # the most the hand held at any step of the lift
                row = self.at_lift[key]
                for k, v in now.items():
                    row[f"lift_{k}"] = max(row[f"lift_{k}"], v)
        return self.loaded.act(obs)

    def summary(self, obs, b: int) -> dict:
        valid = np.asarray(obs["node_valid"][b], bool)
        nodes = np.asarray(obs["nodes"][b])[valid]
        touching = nodes[:, self.contact][:, 0] > 0.5
        finger = nodes[:, self.finger].argmax(axis=1)
        digits = set(finger[touching].tolist()) - {PALM}
        return dict(nodes=int(touching.sum()), digits=len(digits), thumb=THUMB in digits,
                    opposed=THUMB in digits and len(digits) >= 2, palm=bool(touching[finger == PALM].any()),
                    force_n=float(nodes[:, self.force][:, 0].sum() * self.force_scale))


def main(checkpoint: str, hands: str, objects: str, trials: int, settle: float | None) -> None:
    loaded = LoadedPolicy(resolve_checkpoint(checkpoint))
    cfg = loaded.meta.env if settle is None else loaded.meta.env.model_copy(update=dict(settle_s=settle))
    objs = resolve_objects(objects)
    ep = cfg.contract.episode
    table: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for path in hand_specs(tuple(hands.split(",")), None, "HANDS").values():
        spec = load_spec(path)
        recorders: list[Recorder] = []

        def make(env):
            recorders.append(Recorder(env, loaded))
            return recorders[-1]

        records = run_episodes([(spec, o) for o in objs], make, trials, cfg, seed=0)
        names = [o.name for o in objs]
        for r in records:
            why = failure_class(r, ep.lift_height, ep.success_fraction) or "success"
            at = recorders[0].at_lift.get((names.index(r["object"]), r["trial"]))
            if at is not None:  # an episode that ended before the lift (early termination) has no row
                table[(spec.name, why)].append(at)
        print_rows(spec.name, {w: table[(spec.name, w)] for w in OUTCOMES}, flush=True)
    merged = {w: [a for (h, ww), rows in table.items() if ww == w for a in rows] for w in OUTCOMES}
    print_rows("all", merged, flush=True)


def print_rows(label: str, by_outcome: dict[str, list[dict]], flush: bool = False) -> None:
    for why, rows in by_outcome.items():
        if not rows:
            continue
        mean = lambda key: float(np.mean([r[key] for r in rows]))
        print(f"{label:12s} {why:20s} n {len(rows):4d} | lift start: nodes {mean('nodes'):4.1f}  digits "
              f"{mean('digits'):3.1f}  thumb {mean('thumb'):.2f}  opposed {mean('opposed'):.2f}  palm {mean('palm'):.2f}  "
              f"force {mean('force_n'):5.1f} N | most during the lift: nodes {mean('lift_nodes'):4.1f}  opposed "
              f"{mean('lift_opposed'):.2f}  force {mean('lift_force_n'):5.1f} N", flush=flush)


if __name__ == "__main__":
    if len(sys.argv) not in (5, 6):
        sys.exit("usage: tools/probe_lift_start_contacts.py CHECKPOINT HANDS OBJECTS TRIALS [SETTLE_S]")
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), float(sys.argv[5]) if len(sys.argv) == 6 else None)
