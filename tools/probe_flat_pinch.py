"""Can a hand pick a flat object (fork, knife, spoon, marker, scissors) off the table with a different closing
strategy? The scripted grasp of `dgz eval --policy scripted --roll clear --thumb-open 0.5 --guidance 0.05 --settle 2`
against variants of it that differ only in how they close: earlier (a larger palm standoff), with only the thumb
and index (a pinch) or thumb, index and middle (a tripod) closing, or with the wrist
rising along −n while the fingers close (a compliant close: the fingertips slide along the table toward the
thumb instead of jamming on it), or both. Flat objects and four round or boxy controls, seed 0.
docs/training.md, "Flat objects".
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_flat_pinch.py HANDS [VARIANTS] [SLOTS]"""
import numpy as np
from probe_common import CONTROL, e13_scripted, main_grouped, probe

from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.models import FINGER_CLASSES

FLAT = "030_fork,032_knife,031_spoon,040_large_marker,037_scissors"


class CompliantClose(ScriptedGrasp):
    """The scripted grasp with a larger standoff and, while closing, a wrist action of −``rise`` along the palm
    normal (on top of the contract's guidance, which pulls back toward the target: the palm settles about
    rise × wrist_scale / gain above where the guidance holds it) for the first ``rise_steps`` closing steps."""

    def __init__(self, *args, rise: float = 0.0, rise_steps: int = 40, fingers: tuple[str, ...] | None = None,
                 **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.rise, self.rise_steps, self.fingers = rise, rise_steps, fingers
        self.col_finger = self.contract.observation.node_col("finger").start
        self.closed_for: np.ndarray | None = None

    def reset(self, mask=None) -> None:
        super().reset(mask)
        if self.closed_for is not None:
            self.closed_for[slice(None) if mask is None else mask] = 0

    def act(self, obs):
        action = super().act(obs)
        if self.closed_for is None:
            self.closed_for = np.zeros(len(action), np.int64)
        self.closed_for = np.where(self.closing, self.closed_for + 1, 0)
        rising = self.closing & (self.closed_for <= self.rise_steps)
        action[:, 2] = np.where(rising, -self.rise, action[:, 2])
        if self.fingers is not None:  # only these fingers close (a pinch)
            keep = sum(obs["nodes"][:, :, self.col_finger + FINGER_CLASSES.index(f)] for f in self.fingers) > 0
            act = self.contract.action
            fingers = action[:, act.wrist_dim:].reshape(len(action), self.n_nodes, act.n_prim)
            action[:, act.wrist_dim:] = (fingers * keep[:, :, None]).reshape(len(action), -1)
        return action


VARIANTS = {  # (standoff m, rise per step in wrist-action units, rise steps[, closing fingers])
    "scripted": (0.03, 0.0, 0),
    "standoff .06": (0.06, 0.0, 0),
    "rise .15": (0.03, 0.15, 40),
    "rise .3": (0.03, 0.3, 40),
    "standoff .06 rise .15": (0.06, 0.15, 40),
    "pinch": (0.03, 0.0, 0, ("thumb", "index")),
    "tripod": (0.03, 0.0, 0, ("thumb", "index", "middle")),
}


def run(spec, variant, objects: str, slots: int) -> dict:
    standoff, rise, steps, *fingers = variant
    cfg, fields = e13_scripted()
    fields = fields | {"settle_s": 2.0}

    def make(env):
        return CompliantClose(env.N, env.grasp_offset, env.cfg.contract, standoff=standoff, rise=rise,
                              rise_steps=steps, fingers=fingers[0] if fingers else None)

    return probe(spec, cfg.contract, None, slots=slots, objects=objects, env=fields, make_policy=make)


if __name__ == "__main__":
    main_grouped(VARIANTS, run, {"flat": FLAT, "control": CONTROL}, default_slots=5)
