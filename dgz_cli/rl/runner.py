"""Training loop: rollout → PPO update → log → checkpoint, with resume and clean interruption.

Wall-clock is measured per iteration and split into physics, the rest of the env (observations,
rewards), policy forward passes and the PPO update.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from dgz_cli.policy.graph import to_tensors
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.policy.presets import get_preset
from dgz_cli.rl import checkpoint
from dgz_cli.rl.config import TrainConfig
from dgz_cli.rl.normalize import ReturnNormalizer
from dgz_cli.rl.ppo import PPO, PPOConfig
from dgz_cli.rl.storage import RolloutStorage
from dgz_cli.sim.config import EnvConfig, RewardWeights
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes, load_spec

ABLATIONS = {
    "full": dict(),
    "no_physical": dict(use_physical=False),
    "early_fusion": dict(early_fusion=True),
    "no_primitives": dict(),
    "no_mask": dict(use_mask=False),
}


def model_config(cfg: TrainConfig):
    return get_preset(cfg.preset).model_copy(update=ABLATIONS[cfg.ablation])


def env_config(cfg: TrainConfig) -> EnvConfig:
    return EnvConfig(action_mode="joint" if cfg.ablation == "no_primitives" else "primitive",
                     reward=RewardWeights(lift=cfg.lift_weight))


def build_model(meta_policy: dict) -> MAGCN:
    from dgz_cli.policy.presets import MagcnConfig

    return MAGCN(MagcnConfig.model_validate(meta_policy["model"]))


def load_policy(directory: Path) -> tuple[MAGCN, dict]:
    """A trained MAGCN from a checkpoint directory (no pickle)."""
    tensors, meta = checkpoint.load(directory)
    model = build_model(meta["policy"])
    weights = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
    try:
        model.load_state_dict(weights)
    except RuntimeError as exc:
        raise DgzError(f"{directory}: weights do not match the checkpoint's model config ({str(exc).splitlines()[0]})",
                       "the checkpoint is damaged or was written by another dgz version") from None
    model.eval()
    return model, meta


class Trainer:
    def __init__(self, cfg: TrainConfig, out: Path, asset_root: str | None, resume: bool = False,
                 log: Callable[[dict], None] | None = None, on_warm_start: Callable[[dict], None] | None = None) -> None:
        self.cfg, self.out, self.log = cfg, Path(out), log or (lambda row: None)
        self.on_warm_start = on_warm_start or (lambda stats: None)
        torch.manual_seed(cfg.seed)
        self.spec_paths = [resolve_spec(h) for h in cfg.hands]
        specs = [load_spec(p) for p in self.spec_paths]
        objs = resolve_objects(cfg.objects, asset_root)
        pairs = [(s, o) for _ in range(cfg.repeat) for s in specs for o in objs]
        self.env = GraspEnv(pairs, env_config(cfg), seed=cfg.seed, asset_root=asset_root, threads=cfg.threads,
                            use_pen=cfg.ablation != "no_mask")
        self.model = MAGCN(model_config(cfg))
        self.ppo = PPO(self.model, PPOConfig())
        self.storage: RolloutStorage | None = None
        self.reward_norm = ReturnNormalizer(self.env.B, self.ppo.cfg.gamma)
        self.iteration = 0
        self.history: list[dict] = []
        self.warm_start: dict | None = None  # behaviour-cloning statistics, once done
        self.git_revision = checkpoint.git_revision()
        if resume:
            self._resume()
        elif (self.out / "checkpoint.yaml").exists():
            raise DgzError(f"{self.out} already holds a run", "pass --resume to continue it, or choose another --out")

    # ------------------------------------------------------------------ checkpoints
    def meta(self) -> dict:
        return dict(
            dgz_checkpoint=1,
            iteration=self.iteration,
            train=json.loads(self.cfg.model_dump_json()),
            policy=dict(model=json.loads(model_config(self.cfg).model_dump_json()), preset=self.cfg.preset,
                        ablation=self.cfg.ablation, action_mode=env_config(self.cfg).action_mode),
            ppo=json.loads(self.ppo.cfg.model_dump_json()),
            env=json.loads(self.env.cfg.model_dump_json()),
            training_hands={p.stem: checkpoint.spec_hash(p) for p in self.spec_paths},
            git_revision=self.git_revision,  # of the code this process started with
            learning_rate=float(self.ppo.learning_rate),
            reward_normalizer=self.reward_norm.state(),
            last=self.history[-1] if self.history else None,
            warm_start=self.warm_start,
            privileged_inputs=["contact", "force"],  # observed in simulation, absent on hardware
        )

    def save(self) -> None:
        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        tensors.update({f"optim.{k}": v for k, v in self.ppo.optimizer_tensors().items()})
        checkpoint.save(self.out, tensors, self.meta())
        with open(self.out / "history.jsonl", "w") as fh:
            fh.writelines(json.dumps(r) + "\n" for r in self.history)

    def _resume(self) -> None:
        tensors, meta = checkpoint.load(self.out)
        saved = meta.get("policy", {}).get("model")
        if saved != json.loads(model_config(self.cfg).model_dump_json()):
            raise DgzError(f"{self.out}: the checkpoint's model ({meta.get('policy', {}).get('preset')}, "
                           f"{meta.get('policy', {}).get('ablation')}) differs from the requested one",
                           "resume with the same --preset/--ablation, or start a new --out")
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        self.ppo.load_optimizer_tensors({k[6:]: v for k, v in tensors.items() if k.startswith("optim.")},
                                        meta.get("learning_rate"))
        self.iteration = int(meta["iteration"])
        self.warm_start = meta.get("warm_start")
        if meta.get("reward_normalizer"):
            self.reward_norm.load(meta["reward_normalizer"])
        hist = self.out / "history.jsonl"
        if hist.exists():
            self.history = [json.loads(line) for line in hist.read_text().splitlines() if line.strip()]
        torch.manual_seed(self.cfg.seed + self.iteration)

    # ------------------------------------------------------------------ loop
    def train(self) -> None:
        cfg, env = self.cfg, self.env
        try:
            if self.iteration == 0 and cfg.bc_episodes > 0 and self.warm_start is None:
                self.behaviour_clone()
            obs = env.reset(cfg.seed + self.iteration)
            while self.iteration < cfg.iterations:
                obs = self._iteration(obs)
                if self.iteration % cfg.checkpoint_every == 0 or self.iteration == cfg.iterations:
                    self.save()
        except KeyboardInterrupt:
            self.save()
            raise
        finally:
            env.close()

    def behaviour_clone(self) -> None:
        """Warm start from the scripted grasp, then ``bc_dagger_rounds`` DAgger rounds (see
        :mod:`dgz_cli.rl.bc`); saved as iteration 0."""
        from dgz_cli.rl import bc

        cfg, t0 = self.cfg, time.perf_counter()
        collect_s = 0.0
        parts: list = []
        clone_success: list[float] = []
        for round_ in range(cfg.bc_dagger_rounds + 1):
            tc = time.perf_counter()
            torch.set_num_threads(1)
            self.model.eval()
            student = self.model if round_ > 0 else None
            parts.append(bc.collect(self.env, cfg.bc_episodes, self.reward_norm, self.ppo.cfg.gamma,
                                    cfg.seed + round_, student=student))
            if student is not None:
                clone_success.append(round(parts[-1].success_rate, 4))
            collect_s += time.perf_counter() - tc
            torch.set_num_threads(cfg.torch_threads)
            stats = bc.pretrain(self.model, bc.Demonstrations.concat(parts), epochs=cfg.bc_epochs,
                                log_std=cfg.bc_log_std, seed=cfg.seed + round_)
        self.warm_start = dict(teacher="scripted", episodes=sum(p.episodes for p in parts),
                               teacher_success_rate=parts[0].success_rate, dagger_rounds=cfg.bc_dagger_rounds,
                               clone_success_rates=clone_success, collect_s=round(collect_s, 1),
                               fit_s=round(time.perf_counter() - t0 - collect_s, 1), **stats)
        self.ppo.set_learning_rate(cfg.bc_learning_rate)
        self.save()  # iteration 0: the clone alone, before any PPO update
        self.on_warm_start(self.warm_start)

    def _iteration(self, obs: dict) -> dict:
        env, t0 = self.env, time.perf_counter()
        phys0, other0 = env.timing["physics_s"], env.timing["env_other_s"]
        forward_s = 0.0
        episodes: list[dict] = []
        reward_sum = 0.0
        self.model.eval()
        # Small rollout batches run best on one torch thread: the physics workers own the cores then,
        # and OpenMP threads spinning against them cost 100× (measured). The update gets them back.
        torch.set_num_threads(1)
        for _ in range(self.cfg.steps_per_env):
            tf = time.perf_counter()
            obs_t = to_tensors(obs)
            out = self.ppo.act(obs_t)
            forward_s += time.perf_counter() - tf
            if self.storage is None:
                self.storage = RolloutStorage(self.cfg.steps_per_env, env.B, obs_t, env.action_dim, seed=self.cfg.seed)
            next_obs, reward, terminated, truncated, info = env.step(out["action"].numpy())
            # the fixed-length episode end is a termination (no bootstrap); an unstable slot is truncated
            scaled = self.reward_norm(reward.astype(np.float64), terminated | truncated)
            self.storage.add(obs_t, reward=scaled, terminated=terminated, truncated=truncated, **out)
            episodes += list(info["episode"].values())
            reward_sum += float(reward.mean())
            obs = next_obs
        tf = time.perf_counter()
        last_value = self.ppo.value(to_tensors(obs))
        forward_s += time.perf_counter() - tf
        tu = time.perf_counter()
        torch.set_num_threads(self.cfg.torch_threads)
        self.model.train()
        stats = self.ppo.update(self.storage, last_value)
        update_s = time.perf_counter() - tu
        self.iteration += 1
        wall = time.perf_counter() - t0
        row = dict(iteration=self.iteration, wall_s=round(wall, 2), steps_per_s=round(self.cfg.steps_per_env * env.B / wall, 1),
                   physics_s=round(env.timing["physics_s"] - phys0, 2), env_other_s=round(env.timing["env_other_s"] - other0, 2),
                   policy_forward_s=round(forward_s, 2), ppo_update_s=round(update_s, 2),
                   episodes=len(episodes), instabilities=env.instabilities,
                   mean_step_reward=reward_sum / self.cfg.steps_per_env,
                   success_rate=float(np.mean([e["success"] for e in episodes])) if episodes else None,
                   mean_return=float(np.mean([e["return_"] for e in episodes])) if episodes else None,
                   **{k: float(np.mean([e[k] for e in episodes])) if episodes else None
                      for k in ("r_dis", "r_contact", "r_force", "r_reg", "r_pen", "r_lift", "max_rise")},
                   learning_rate=float(self.ppo.learning_rate),
                   **{k: float(v) for k, v in stats.items() if k != "learning_rate"})
        self.history.append(row)
        self.log(row)
        return obs


def write_curve(history: list[dict], path: Path) -> None:
    """Training curve PNG (success rate and mean return per iteration), written atomically."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ended = [h for h in history if h["success_rate"] is not None]  # iterations in which episodes ended
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.5))
    ax[0].plot([h["iteration"] for h in ended], [h["success_rate"] for h in ended], marker=".")
    ax[0].set(xlabel="iteration", ylabel="success rate (episodes ended in the iteration)", ylim=(0, 1))
    ax[1].plot([h["iteration"] for h in ended], [h["mean_return"] for h in ended], marker=".")
    ax[1].set(xlabel="iteration", ylabel="mean episode return")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def write_csv(history: list[dict], path: Path) -> None:
    if not history:
        return
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(history[-1]))
        w.writeheader()
        w.writerows(history)
