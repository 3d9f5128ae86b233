"""Is a policy's wrist-translation residual conditioned on the hand? (issue 11, docs/training.md after E21.) A
checkpoint in its own env, on one object, several hands, the same start states: per window of control steps the
mean wrist residual as applied (the policy's action × the contract's residual gains, clipped, × ``wrist_scale``; mm
per step along the palm's f, l, n axes and mrad about them), the contract's guidance (mm per step), the palm's gap
to the object surface and the object's displacement, split by whether the episode pushed the object more than
`dgz eval`'s 5 cm during the grasp phase or ended on the push limit (the env then starts a new episode in that slot,
whose steps are left out). A residual of r mm per step against a guidance gain g settles where the
guidance pulls back as hard, r / g mm off the guidance's grasp point: the offset the policy learned.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/trace_wrist_residual.py CHECKPOINT HANDS OBJECT TRIALS"""
import sys

import numpy as np

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import PUSHED, make_env, palm_object_distance
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec

WINDOWS = ((0, 20), (20, 40), (40, 60), (60, 80), (80, 100), (100, 120))


def trace(policy: LoadedPolicy, hand: str, obj: str, trials: int) -> None:
    cfg = policy.meta.env.model_copy(update=dict(early_stop=False))
    act = cfg.contract.action
    env = make_env([(load_spec(resolve_spec(hand)), resolve_objects(obj)[0])] * trials, cfg, seed=0, threads=2)
    obs = env.reset(0)
    policy.reset(None)
    steps = cfg.contract.episode.grasp_steps
    gains = act.residual_gains(env.N)[: act.wrist_dim]
    residual, guidance = np.zeros((steps, trials, 6)), np.zeros((steps, trials, 6))
    gap, displacement = np.zeros((steps, trials)), np.zeros((steps, trials))
    start = env.state()["obj_pos"].copy()
    live, ended_pushed = np.ones(trials, bool), np.zeros(trials, bool)
    for t in range(steps):
        a = np.asarray(policy.act(obs), dtype=np.float64)
        residual[t] = np.clip(a[:, : act.wrist_dim] * gains, -1, 1) * act.wrist_scale
        guidance[t] = env.guidance(obs["global"], obs["nodes"])
        gap[t] = palm_object_distance(env)[0]
        displacement[t] = np.linalg.norm(env.state()["obj_pos"] - start, axis=-1)
        for series in (residual, guidance, gap, displacement):
            series[t, ~live] = np.nan
        obs, _, terminated, truncated, _ = env.step(a)
        ended_pushed |= live & terminated
        live &= ~(terminated | truncated)
    pushed = ended_pushed | (np.nanmax(displacement, 0) > PUSHED)
    print(f"{hand} {obj}: pushed {pushed.sum()}/{trials}; guidance gain {cfg.contract.guidance.gain}")
    for lo, hi in WINDOWS:
        for name, m in (("pushed", pushed), ("kept", ~pushed)):
            if m.any():
                r, g = np.nanmean(residual[lo:hi, m], (0, 1)) * 1000, np.nanmean(guidance[lo:hi, m], (0, 1)) * 1000
                print(f"  steps {lo:3d}-{hi:3d} {name:6s} residual f/l/n mm {np.round(r[:3], 2)} rot mrad "
                      f"{np.round(r[3:], 2)} guidance mm {np.round(g[:3], 2)} gap {np.nanmean(gap[lo:hi, m]):.3f} "
                      f"displacement {np.nanmean(displacement[lo:hi, m]):.3f}")
    r = np.nanmean(residual[20:100], (0, 1))[:3] * 1000
    if cfg.contract.guidance.gain > 0:
        print(f"  steps 20-100 all: residual f/l/n mm {np.round(r, 2)} → settles "
              f"{np.round(r / cfg.contract.guidance.gain, 1)} mm off the grasp point", flush=True)


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    for hand in sys.argv[2].split(","):
        trace(policy, hand, sys.argv[3], int(sys.argv[4]))


if __name__ == "__main__":
    main()
