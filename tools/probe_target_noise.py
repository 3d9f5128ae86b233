"""How does a policy fare when its grasp target is off? A checkpoint evaluated in its own env (eval's protocol) on
the same start states, but with the grasp target the guidance steers to and the policy observes shifted per episode
by a horizontal Gaussian offset of std NOISE m per axis (the env's training-only `target_noise`, switched back on
for this probe; a single camera's centroid is biased like this). Per hand: the success rate and the failure
classes.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_target_noise.py CHECKPOINT HANDS OBJECTS TRIALS NOISE`"""
import json
import sys

from probe_common import checkpoint_summary

from dgz_cli.rl.checkpoint import LoadedPolicy


def main() -> None:
    if len(sys.argv) != 6:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    objects, trials, noise = sys.argv[3], int(sys.argv[4]), float(sys.argv[5])

    def noisy(env):
        # run_episodes builds its env through make_env (noise off) and resets it after this call
        env.cfg = env.cfg.model_copy(update=dict(target_noise=noise))
        return policy

    out = {}
    for hand in sys.argv[2].split(","):
        summary = checkpoint_summary(policy, hand, objects, trials, noisy)
        out[hand] = dict(success=round(summary["success_rate"], 3), failures=summary["failures"])
        print(hand, json.dumps(out[hand]), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
