"""Behaviour cloning of searched grasps into a checkpoint (issue 11, rung E47): the demonstrations are the
per-start open-loop residuals that ``tools/probe_open_loop_search.py`` found (one JSON line per search, ``best``
1.0 = the searched residual lifted the object from that start), replayed from the same start in the search's
contract (the checkpoint's, with ``finger_residual`` and ``wrist_residual`` 1.0 and the aim range AIM). A line
of ``tools/pick_pair_residuals.py`` (one residual per pair, with ``demo_starts`` and ``demo_seed``) instead gives
the episodes in which that one residual lifts the object from ``demo_starts`` starts (one env, seed ``demo_seed``),
so that a pair's demonstrations agree with each other. The
anchor is the checkpoint's own mean action on one episode per (training hand, object) slot, so that what it
already grasps is kept.

The checkpoint's actor is first rescaled to the search's contract (``dgz_cli.rl.runner.keep_commands``: the
same commands from scaled outputs), then its mean is regressed onto both (MSE over the valid action dims, the
demonstrations repeated REPEAT times), and the result is written as a checkpoint in the search's contract that
``dgz eval`` and ``dgz train --init-from`` take as is.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/bc_searched.py CHECKPOINT OUT EPOCHS LR REPEAT
SEARCH_LOG... [--anchor-hands H,H,...]` (run from the repo root; the anchor's hands default to the four training
hands and take what ``dgz train --hands`` takes, ``generated:DIR`` included) prints the replay check of every
demonstration, the losses before and after on demonstrations and anchor separately, and writes OUT."""
import sys
import time
from pathlib import Path

import numpy as np
import torch

from probe_open_loop_search import AIM, Candidate, finger_masks_of, lifted_per_start, search_contract, search_lines

from dgz_cli.cli.hand_refs import hand_specs
from dgz_cli.policy.graph import to_tensors
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.rl import checkpoint
from dgz_cli.rl.bc import Demonstrations, pretrain
from dgz_cli.rl.config import env_config
from dgz_cli.rl.runner import keep_commands
from dgz_cli.rl.storage import STATIC_KEYS
from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec

ANCHOR_HANDS, ANCHOR_SEED = ("allegro", "shadow", "schunk_svh", "ability"), 4711
STATIC = STATIC_KEYS


def record(env, act) -> tuple[list[dict], np.ndarray, list[dict], dict]:
    """One episode in every slot of ``env``, acting ``act(obs, t)`` (B, A): per step the observation's nodes and
    global, the actions (T, B, A), each slot's first episode record and the static observation keys."""
    obs = env.reset()  # the seed the env was built with
    steps, actions, first = [], [], {}
    for _ in range(env.cfg.contract.episode.episode_steps):
        a = act(obs, env.t.copy())
        steps.append({k: np.array(obs[k]) for k in ("nodes", "global")})
        actions.append(a)
        obs, _, _, _, info = env.step(a)
        for b, ep in info["episode"].items():
            first.setdefault(b, ep)
    static = {k: np.array(obs[k]) for k in STATIC}
    return steps, np.stack(actions), [first[b] for b in range(env.B)], static


def slots(part: tuple[list[dict], np.ndarray, dict], keep: list[int]) -> tuple[list[dict], np.ndarray, dict]:
    """The recorded slots ``keep`` of one recording (steps, actions (T, B, A), static)."""
    steps, actions, static = part
    return ([{k: v[keep] for k, v in s.items()} for s in steps], actions[:, keep],
            {k: v[keep] for k, v in static.items()})


def to_demos(parts: list[tuple[list[dict], np.ndarray, dict]], n_max: int) -> Demonstrations:
    """Stack recorded slots (steps, actions (T, B, A), static) into one :class:`Demonstrations`, nodes padded
    to ``n_max`` (padded nodes are invalid and their action dims zero)."""
    nodes, glob, acts, static = [], [], [], {k: [] for k in STATIC}
    for steps, actions, st in parts:
        n = st["node_valid"].shape[1]
        pad = n_max - n
        nodes.append(np.pad(np.stack([s["nodes"] for s in steps]), ((0, 0), (0, 0), (0, pad), (0, 0))))
        glob.append(np.stack([s["global"] for s in steps]))
        acts.append(np.pad(actions, ((0, 0), (0, 0), (0, 3 * pad))))
        static["adjacency"].append(np.pad(st["adjacency"], ((0, 0), (0, pad), (0, pad))))
        static["physical"].append(np.pad(st["physical"], ((0, 0), (0, pad), (0, 0))))
        static["mask"].append(np.pad(st["mask"], ((0, 0), (0, pad), (0, 0))))
        static["node_valid"].append(np.pad(st["node_valid"], ((0, 0), (0, pad))))
    t = {k: torch.as_tensor(np.concatenate(v), dtype=torch.bool if k == "node_valid" else torch.float32)
         for k, v in static.items()}
    actions = torch.as_tensor(np.concatenate(acts, axis=1), dtype=torch.float32)
    return Demonstrations(static=t, nodes=torch.as_tensor(np.concatenate(nodes, axis=1), dtype=torch.float32),
                          global_=torch.as_tensor(np.concatenate(glob, axis=1), dtype=torch.float32), actions=actions,
                          returns=torch.zeros(actions.shape[:2]), success_rate=0.0, episodes=actions.shape[1])


def action_loss(model, demos: Demonstrations) -> float:
    with torch.no_grad():
        T, B = demos.actions.shape[:2]
        tot, cnt = 0.0, 0.0
        for t in range(0, T, 10):
            tt, bb = torch.full((B,), t), torch.arange(B)
            obs = demos.obs(tt, bb)
            mean = model(obs)[0]
            av = model.action_valid(obs).float()
            tot += float((((mean - demos.actions[tt, bb]) ** 2) * av).sum())
            cnt += float(av.sum())
    return tot / cnt


def main(source: str, out: str, epochs: int, lr: float, repeat: int, logs: list[str],
         anchor_hands: tuple[str, ...] = ANCHOR_HANDS) -> None:
    t0 = time.time()
    torch.manual_seed(0)
    tensors, meta = checkpoint.load(Path(source))
    contract = search_contract(meta.contract, AIM)
    cfg = meta.env.model_copy(update=dict(contract=contract))
    model = MAGCN(meta.model, contract)
    model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
    ratios = keep_commands(model, meta.contract, contract)
    model.eval()
    print(f"rescaled to the search's contract: {ratios}", flush=True)

    demos, kept, n_max = [], [], 0
    for s in search_lines(logs):
        picked = "demo_starts" in s  # a tools/pick_pair_residuals.py line: one residual from many starts
        if not picked and not lifted_per_start(s):
            continue
        spec = load_spec(resolve_spec(s["hand"]))
        (obj,) = resolve_objects(s["object"])
        starts, seed = (s["demo_starts"], s["demo_seed"]) if picked else (1, s["seed"])
        env = make_env([(spec, obj)] * starts, cfg, seed=seed)
        candidate = Candidate(np.array(s["best_theta"]), finger_masks_of(spec)[1], contract.action, s.get("rot", 1.0))
        steps, actions, eps, static = record(env, lambda obs, t: candidate.action(t))
        env.close()
        ok = [b for b in range(starts) if eps[b]["success"]]
        print(f"replay {s['hand']} {s['object']} seed {seed}: lifted from {len(ok)} of {starts}", flush=True)
        if ok:
            demos.append(slots((steps, actions, static), ok))
            kept.append(f"{s['hand']}/{s['object']}/{seed}" + (f"/{len(ok)}of{starts}" if picked else ""))
            n_max = max(n_max, static["node_valid"].shape[1])
    specs = hand_specs(anchor_hands, None, "--anchor-hands")
    pairs = [(load_spec(p), o) for p in specs.values() for o in resolve_objects("ycb45")]
    env = make_env(pairs, cfg, seed=ANCHOR_SEED)
    steps, actions, eps, static = record(env, lambda obs, t: model.act(to_tensors(obs)).numpy())
    env.close()
    anchor_success = float(np.mean([e["success"] for e in eps]))
    n_max = max(n_max, static["node_valid"].shape[1])
    print(f"anchor: {len(pairs)} slots, the rescaled checkpoint lifts {anchor_success:.3f}; "
          f"{sum(a.shape[1] for _, a, _ in demos)} demonstrations from {len(demos)} recordings; {time.time() - t0:.0f} s", flush=True)
    anchor_set = to_demos([(steps, actions, static)], n_max)
    demo_set = to_demos(demos, n_max) if demos else None
    losses = lambda: (action_loss(model, demo_set) if demos else float("nan"), action_loss(model, anchor_set))
    before = losses()
    both = to_demos(demos * repeat + [(steps, actions, static)], n_max)
    stats = pretrain(model, both, epochs=epochs, learning_rate=lr, value_coef=0.0, seed=0) if epochs else {}
    after = losses()
    print(f"action MSE demonstrations {before[0]:.4f} -> {after[0]:.4f}, anchor {before[1]:.4f} -> {after[1]:.4f} "
          f"({stats}); {time.time() - t0:.0f} s", flush=True)
    train = meta.train.model_copy(update=dict(finger_residual=1.0, wrist_residual=1.0, guidance_aim_residual=AIM,
                                              init_from=source))
    warm = dict(teacher="searched grasps", checkpoint=source, checkpoint_iteration=meta.iteration,
                weights_sha256=meta.weights_sha256, demonstrations=kept, repeat=repeat, epochs=epochs,
                learning_rate=lr, anchor_hands=sorted(specs), anchor_slots=len(pairs), anchor_seed=ANCHOR_SEED, action_rescale=ratios,
                mse_before=[round(x, 5) for x in before], mse_after=[round(x, 5) for x in after])
    if env_config(train).contract != contract:
        raise SystemExit("the run config does not give the search's contract")
    new_meta = meta.model_copy(update=dict(train=train, env=cfg, warm_start=warm, git_revision=checkpoint.git_revision()))
    Path(out).mkdir(parents=True, exist_ok=True)
    checkpoint.save(Path(out), {f"model.{k}": v for k, v in model.state_dict().items()}, new_meta)
    checkpoint.read_meta(Path(out))
    print(f"wrote {out}; {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    anchor = ANCHOR_HANDS
    if "--anchor-hands" in args:
        i = args.index("--anchor-hands")
        anchor = tuple(args[i + 1].split(","))
        del args[i:i + 2]
    if len(args) < 6:
        sys.exit(__doc__)
    main(args[0], args[1], int(args[2]), float(args[3]), int(args[4]), args[5:], anchor)
