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
from dgz_cli.policy.presets import MagcnConfig, get_preset
from dgz_cli.rl import checkpoint
from dgz_cli.rl.checkpoint import CheckpointMeta, NormalizerState
from dgz_cli.rl.config import TrainConfig
from dgz_cli.rl.normalize import ReturnNormalizer
from dgz_cli.rl.ppo import PPO
from dgz_cli.rl.stop import StopRequest
from dgz_cli.rl.storage import RolloutStorage
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes

ABLATION_MODEL = {
    "full": dict(),
    "no_physical": dict(use_physical=False),
    "early_fusion": dict(early_fusion=True),
    "no_primitives": dict(),
    "no_mask": dict(use_mask=False),
}


PAIR_EMA = 0.2  # prioritised sampling: weight of a new episode outcome in its pair's success EMA
SEPARATE_CRITIC_WIDTHS = (32, 32, 32, 32)  # ~0.4 of compact's trunk FLOPs: 4 hops, cheap next to the actor


def model_config(cfg: TrainConfig) -> MagcnConfig:
    update = dict(ABLATION_MODEL[cfg.ablation], log_std_per_type=cfg.log_std_per_type,
                  critic_widths=SEPARATE_CRITIC_WIDTHS if cfg.critic == "separate" else None)
    if cfg.init_log_std is not None:
        update["init_log_std"] = cfg.init_log_std
    return get_preset(cfg.preset).model_copy(update=update)


class Trainer:
    """PPO on an env it is given (``GraspEnv`` or anything with its ``reset``/``step``/``B``/``action_dim``/
    ``cfg``/``timing``/``instabilities``/``close``, and ``pair_names`` for prioritised sampling).
    ``training_hands`` maps each hand name to its spec's sha256, recorded in every checkpoint. ``init``
    (tensors, manifest, name) is the checkpoint a new run fine-tunes (``cfg.init_from``, loaded by the caller);
    a resumed run ignores it, its own checkpoint holds the weights."""

    def __init__(self, cfg: TrainConfig, env, out: Path, training_hands: dict[str, str], resume: bool = False,
                 log: Callable[[dict], None] | None = None, on_warm_start: Callable[[dict], None] | None = None,
                 teacher_factory: Callable[[object], object] | None = None,
                 init: tuple[dict, CheckpointMeta, str] | None = None) -> None:
        self.cfg, self.env, self.out, self.log = cfg, env, Path(out), log or (lambda row: None)
        self.on_warm_start = on_warm_start or (lambda stats: None)
        self.teacher_factory = teacher_factory
        self.training_hands = dict(training_hands)
        torch.manual_seed(cfg.seed)
        self.model = MAGCN(model_config(cfg), env.cfg.contract)
        self.ppo = PPO(self.model, cfg.ppo)
        self.storage: RolloutStorage | None = None
        self.reward_norm = ReturnNormalizer(self.env.B, cfg.ppo.gamma)
        self.iteration = 0
        self.history: list[dict] = []
        self.stop = StopRequest()  # set by `dgz train`'s signal handler, honoured between steps
        self.warm_start: dict | None = None  # behaviour-cloning statistics, once done
        self.pair_success: dict[str, float] = {}  # 'hand/object' → success EMA (prioritised sampling)
        self.git_revision = checkpoint.git_revision()
        if resume:
            self._resume()
        elif (self.out / checkpoint.META_FILE).exists():
            raise DgzError(f"{self.out} already holds a run", "pass --resume to continue it, or choose another --out")
        elif init is not None:
            self._init_from(*init)
        self.ppo.enforce_std_bounds()  # a fine-tune's or resumed run's first rollout already explores within them

    # ------------------------------------------------------------------ checkpoints
    def meta(self) -> CheckpointMeta:
        return CheckpointMeta(
            iteration=self.iteration, weights="model.safetensors", train=self.cfg, model=self.model.cfg,
            env=self.env.cfg, training_hands=self.training_hands, git_revision=self.git_revision,
            learning_rate=float(self.ppo.learning_rate), reward_normalizer=NormalizerState(**self.reward_norm.state()),
            last=self.history[-1] if self.history else None, warm_start=self.warm_start,
            pair_success=self.pair_success or None)

    def save(self) -> None:
        if not all(bool(torch.isfinite(p).all()) for p in self.model.parameters()):
            raise DgzError(f"training diverged at iteration {self.iteration}: non-finite weights; not saved",
                           f"resume from the last checkpoint in {self.out} with a smaller learning rate or reward weights")
        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        tensors.update({f"optim.{k}": v for k, v in self.ppo.optimizer_tensors().items()})
        atomic_write_bytes(self.out / "history.jsonl", "".join(json.dumps(r) + "\n" for r in self.history).encode())
        checkpoint.save(self.out, tensors, self.meta())

    def _resume(self) -> None:
        tensors, meta = checkpoint.load(self.out)
        if meta.model != self.model.cfg or meta.contract != self.env.cfg.contract:
            raise DgzError(f"{self.out}: the checkpoint's model ({meta.train.preset}, {meta.train.ablation}) or control "
                           "contract differs from the requested one",
                           "resume with the same --preset/--ablation and env options, or start a new --out")
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        self.ppo.load_optimizer_tensors({k[6:]: v for k, v in tensors.items() if k.startswith("optim.")},
                                        meta.learning_rate)
        self.iteration = meta.iteration
        self.warm_start = meta.warm_start
        self.pair_success = dict(meta.pair_success or {})
        if meta.reward_normalizer is not None:
            self.reward_norm.load(meta.reward_normalizer.model_dump())
        hist = self.out / "history.jsonl"
        if hist.exists() or hist.is_symlink():
            from dgz_cli.rl.history import read_history

            self.history = read_history(hist, self.iteration)  # schema-checked: one line naming file and field
        torch.manual_seed(self.cfg.seed + self.iteration)

    def _init_from(self, tensors: dict, meta: CheckpointMeta, name: str) -> None:
        """Fine-tuning: the model weights (exploration std included) and the return normalizer of checkpoint
        ``name`` start the run; the optimizer starts fresh at the configured learning rate. Recorded as the
        run's warm start."""
        where = f"--init-from {name}"
        if meta.student is not None:
            raise DgzError(f"{where}: is a distilled student", "fine-tune a `dgz train` checkpoint (its teacher)")
        for what, theirs, ours in (("model", meta.model.model_dump(), self.model.cfg.model_dump()),
                                   ("control contract", _without_fine_tunable(meta.contract),
                                    _without_fine_tunable(self.env.cfg.contract))):
            if theirs != ours:
                raise DgzError(f"{where}: its {what} differs from this run's (at {first_difference(theirs, ours)})",
                               "--init-from takes its run config from the checkpoint; drop the option or --config "
                               f"entry that changes it (only {', '.join(FINE_TUNABLE)} may change)")
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        rescaled = keep_commands(self.model, meta.contract, self.env.cfg.contract)
        if meta.reward_normalizer is not None:
            self.reward_norm.load(meta.reward_normalizer.model_dump())
        self.warm_start = dict(teacher="checkpoint", checkpoint=name, checkpoint_iteration=meta.iteration,
                               weights_sha256=meta.weights_sha256, checkpoint_training_hands=sorted(meta.training_hands))
        if rescaled is not None:
            self.warm_start["action_rescale"] = rescaled

    # ------------------------------------------------------------------ loop
    def train(self) -> None:
        cfg, env = self.cfg, self.env
        try:
            if self.iteration == 0 and cfg.bc_episodes > 0 and self.warm_start is None:
                self.behaviour_clone()
            obs = env.reset(cfg.seed + self.iteration)
            while self.iteration < cfg.iterations:
                obs = self.iterate(obs)
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
            parts.append(bc.collect(self.env, self.teacher_factory(self.env), cfg.bc_episodes, self.reward_norm,
                                    self.ppo.cfg.gamma, cfg.seed + round_, student=student,
                                    check_stop=self.stop.check))
            if student is not None:
                clone_success.append(round(parts[-1].success_rate, 4))
            collect_s += time.perf_counter() - tc
            torch.set_num_threads(cfg.torch_threads)
            stats = bc.pretrain(self.model, bc.Demonstrations.concat(parts), epochs=cfg.bc_epochs,
                                log_std=cfg.bc_log_std, seed=cfg.seed + round_, check_stop=self.stop.check)
        self.warm_start = dict(teacher="scripted", episodes=sum(p.episodes for p in parts),
                               teacher_success_rate=parts[0].success_rate, dagger_rounds=cfg.bc_dagger_rounds,
                               clone_success_rates=clone_success, collect_s=round(collect_s, 1),
                               fit_s=round(time.perf_counter() - t0 - collect_s, 1), **stats)
        self.ppo.set_learning_rate(cfg.bc_learning_rate)
        self.save()  # iteration 0: the clone alone, before any PPO update
        self.on_warm_start(self.warm_start)

    def env_priority(self, episodes: list[dict]) -> np.ndarray:
        """(B,) sampling weights: (1 − success EMA of the env's hand/object pair) + ``failure_priority``, after
        folding this iteration's ended ``episodes`` into the EMAs (rate PAIR_EMA; a new pair starts at its first
        outcome)."""
        for e in episodes:
            key = f"{e['hand']}/{e['object']}"
            old = self.pair_success.get(key)
            self.pair_success[key] = float(e["success"]) if old is None else old + PAIR_EMA * (float(e["success"]) - old)
        return np.array([1.0 - self.pair_success.get(k, 0.0) + self.cfg.failure_priority for k in self.env.pair_names])

    def iterate(self, obs: dict) -> dict:
        """One PPO iteration from observation ``obs``: ``steps_per_env`` rollout steps in every env, then the
        update; appends its row to ``history`` (and logs it) and returns the next observation. No checkpoint."""
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
            self.stop.check()
            tf = time.perf_counter()
            obs_t = to_tensors(obs)
            out = self.ppo.act(obs_t)
            forward_s += time.perf_counter() - tf
            if self.storage is None:
                self.storage = RolloutStorage(self.cfg.steps_per_env, env.B, obs_t, env.action_dim, seed=self.cfg.seed)
            next_obs, reward, terminated, truncated, info = env.step(out["action"].numpy())
            scaled = self.reward_norm(reward.astype(np.float64), terminated | truncated)
            final_value = None
            if "final_obs" in info:  # truncated slots bootstrap from the value of their last observation
                final_value = self.ppo.value(to_tensors({**obs_t, **info["final_obs"]}))
            self.storage.add(obs_t, reward=scaled, terminated=terminated, truncated=truncated,
                             final_value=final_value, **out)
            episodes += list(info["episode"].values())
            reward_sum += float(reward.mean())
            obs = next_obs
        if self.cfg.failure_priority is not None:
            self.storage.set_env_priority(self.env_priority(episodes))
        tf = time.perf_counter()
        last_value = self.ppo.value(to_tensors(obs))
        forward_s += time.perf_counter() - tf
        tu = time.perf_counter()
        torch.set_num_threads(self.cfg.torch_threads)
        self.model.train()
        stats = self.ppo.update(self.storage, last_value, critic_only=self.iteration < self.cfg.critic_warmup)
        update_s = time.perf_counter() - tu
        self.iteration += 1
        wall = time.perf_counter() - t0
        row = dict(iteration=self.iteration, wall_s=round(wall, 2), steps_per_s=round(self.cfg.steps_per_env * env.B / wall, 1),
                   # 0.1 ms resolution: a short benchmark iteration's split must not round to zero
                   physics_s=round(env.timing["physics_s"] - phys0, 4), env_other_s=round(env.timing["env_other_s"] - other0, 4),
                   policy_forward_s=round(forward_s, 4), ppo_update_s=round(update_s, 4),
                   episodes=len(episodes), instabilities=env.instabilities,
                   mean_step_reward=reward_sum / self.cfg.steps_per_env,
                   success_rate=float(np.mean([e["success"] for e in episodes])) if episodes else None,
                   mean_return=float(np.mean([e["return_"] for e in episodes])) if episodes else None,
                   **{k: float(np.mean([e[k] for e in episodes])) if episodes else None
                      for k in [f"r_{t}" for t in env.terms] + ["max_rise"]},
                   learning_rate=float(self.ppo.learning_rate),
                   **{k: float(v) for k, v in stats.items() if k != "learning_rate"})
        self.history.append(row)
        self.log(row)
        return obs


RESIDUAL_FACTORS = ("wrist_residual", "wrist_translation_residual", "finger_residual")
FINE_TUNABLE = tuple(f"action.{k}" for k in RESIDUAL_FACTORS) + (
    "guidance.stop_gap", "guidance.aim_residual", "guidance.aim_axes")


@torch.no_grad()
def keep_commands(model: MAGCN, old: ControlContract, new: ControlContract) -> dict[str, list] | None:
    """A fine-tune that changes the residual factors or the aim range (``old`` → ``new`` control contract)
    starts from the checkpoint's commands: the actor's output layers and log-stds are scaled per action dim by
    old / new :meth:`ControlContract.action_units`, so mean and exploration command what they did (identical
    wherever the old command was not clipped). A dim whose amount was 0 in the checkpoint commanded nothing, so
    its output was never shaped by a consequence: it starts at a zero mean and the model's initial log-std. A
    dim whose kind changes (velocity ↔ aim shift) or whose new amount is 0 keeps its weights. Returns what was
    applied ({'wrist': ratios (wrist_dim,), 'finger': [ratio]}, plus 'started_at_zero': the wrist dims and
    'fingers' that start at zero) or None when nothing changed."""
    old_kinds, old_wrist, old_finger = old.action_units()
    new_kinds, new_wrist, new_finger = new.action_units()
    wrist = np.ones(len(new_kinds))
    for i, (ko, kn, ao, an) in enumerate(zip(old_kinds, new_kinds, old_wrist, new_wrist)):
        if ko == kn and ao > 0 and an > 0:
            wrist[i] = ao / an
    finger = old_finger / new_finger if old_finger > 0 and new_finger > 0 else 1.0
    zero_wrist = [i for i, (ao, an) in enumerate(zip(old_wrist, new_wrist)) if ao == 0 and an > 0]
    zero_fingers = old_finger == 0 and new_finger > 0
    if np.allclose(wrist, 1.0) and finger == 1.0 and not zero_wrist and not zero_fingers:
        return None
    w = torch.as_tensor(wrist, dtype=torch.float32)
    head = model.wrist_head[-1]
    head.weight.mul_(w[:, None])
    head.bias.mul_(w)
    model.log_std_wrist.add_(torch.log(w))
    head.weight[zero_wrist] = 0.0
    head.bias[zero_wrist] = 0.0
    model.log_std_wrist[zero_wrist] = model.cfg.init_log_std
    head = model.node_head[-1]
    head.weight.mul_(0.0 if zero_fingers else finger)
    head.bias.mul_(0.0 if zero_fingers else finger)
    if zero_fingers:
        model.log_std_prim.fill_(model.cfg.init_log_std)
    else:
        model.log_std_prim.add_(float(np.log(finger)))
    applied: dict[str, list] = dict(wrist=[round(float(x), 6) for x in wrist], finger=[round(float(finger), 6)])
    if zero_wrist or zero_fingers:
        applied["started_at_zero"] = zero_wrist + (["fingers"] if zero_fingers else [])
    return applied


def _without_fine_tunable(contract) -> dict:
    """The contract as a dict, less the fields a fine-tune may change (``FINE_TUNABLE``: the action's residual
    factors, the guidance's stop gap, aim residual and aim axes): they change how the command is composed, not
    any tensor's shape or meaning."""
    dump = contract.model_dump()
    for path in FINE_TUNABLE:
        part, field = path.split(".")
        dump[part] = {k: v for k, v in dump[part].items() if k != field}
    return dump


def first_difference(a, b, path: str = "") -> str:
    """Dotted path of the first field where two nested dicts (``model_dump`` output) differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            if a.get(k) != b.get(k):
                return first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else str(k))
    return path or "(top level)"


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
