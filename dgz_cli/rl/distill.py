"""`dgz distill`'s loop: DAgger behaviour cloning of a privileged teacher into a student, then optional PPO.

Paper Sec. III-D and Supp. "Privileged Distillation Details": the student (:mod:`dgz_cli.policy.student`,
the teacher's MAGCN without contact/force plus an LSTM over the last 5 steps) is initialised from the
teacher and trained by MSE between its action means and the teacher's; no value or entropy term. DAgger
(Ross et al. 2011): each iteration the *student* acts (its mean action) for ``steps_per_env`` control steps
in every env, on the observation hardware gives (the env applies the run's
:class:`~dgz_cli.spec.hardware_view.HardwareView`), while the teacher labels every visited state with its
mean action on the simulator's full, unperturbed observation of the same state (``env.teacher_obs``; with
``teacher_view: student``, on the student's observation plus the privileged contact and force). The
labelled steps of the latest ``buffer_iterations`` iterations are aggregated and the student is fitted for
``epochs`` passes (MSE over the valid action dims, as in :func:`dgz_cli.rl.bc.pretrain`). Then, if asked,
``finetune_iterations`` PPO iterations on the task reward (the teacher's PPO settings and reward scale;
rollouts carry the history in the observation, so the storage and the update need nothing else).

The env is handed in by the composition root (``dgz_cli.cli.distill_cmd``): a ``HardwareViewEnv`` under
the student's env config, with ``teacher_layout`` so that ``teacher_obs`` is filled. Episodes run on across
iterations (like ``dgz train``); a slot's history is reset when its episode ends.

Checkpoints are written like ``dgz train``'s (atomic, safetensors + YAML, format 3 with a ``student``
section); ``--resume`` continues from the last one. The DAgger data are not saved: a resumed run starts
with an empty buffer (the next iteration refills it).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from dgz_cli.policy.graph import to_tensors
from dgz_cli.policy.magcn import MAGCN
from dgz_cli.policy.student import StudentMAGCN, TokenHistory, init_from_teacher, student_obs, tokens
from dgz_cli.rl import checkpoint
from dgz_cli.rl.checkpoint import STUDENT_FORMAT, CheckpointMeta, NormalizerState
from dgz_cli.rl.distill_config import DistillConfig, StudentMeta
from dgz_cli.rl.normalize import ReturnNormalizer
from dgz_cli.rl.ppo import PPO
from dgz_cli.rl.stop import StopRequest
from dgz_cli.rl.storage import STATIC_KEYS, RolloutStorage
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes


class Distiller:
    """DAgger + optional PPO of a student on ``env`` (see the module docstring).

    ``teacher``: the teacher's MAGCN (eval mode); ``teacher_meta``: its manifest; ``teacher_path``: where it
    was loaded from; ``training_hands``: hand name → spec sha256 (recorded)."""

    def __init__(self, cfg: DistillConfig, env, teacher: MAGCN, teacher_meta: CheckpointMeta, teacher_path: str,
                 out: Path, training_hands: dict[str, str], resume: bool = False,
                 log: Callable[[dict], None] | None = None) -> None:
        self.cfg, self.env, self.teacher, self.teacher_meta = cfg, env, teacher, teacher_meta
        self.out, self.log = Path(out), log or (lambda row: None)
        self.teacher_path, self.training_hands = teacher_path, dict(training_hands)
        torch.manual_seed(cfg.seed)
        self.model = StudentMAGCN(teacher_meta.model, env.cfg.contract, cfg.student)
        self.init_stats = init_from_teacher(self.model, teacher.state_dict(), teacher_meta.contract.observation)
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=cfg.learning_rate)
        self.ppo: PPO | None = None
        self.reward_norm = ReturnNormalizer(env.B, teacher_meta.train.ppo.gamma)
        if teacher_meta.reward_normalizer is not None:  # PPO continues on the teacher's reward scale
            self.reward_norm.load(teacher_meta.reward_normalizer.model_dump())
        self.dagger_done = self.finetune_done = 0
        self.history: list[dict] = []
        self.stop = StopRequest()  # set by `dgz distill`'s signal handler, honoured between steps
        self.buffer: list[dict[str, torch.Tensor]] = []
        self.hist = TokenHistory(env.B, cfg.student.history, self.model.token_dim)
        self.obs: dict | None = None
        self.storage: RolloutStorage | None = None
        self.git_revision = checkpoint.git_revision()
        self.gen = torch.Generator().manual_seed(cfg.seed)
        if resume:
            self._resume()
        elif (self.out / checkpoint.META_FILE).exists():
            raise DgzError(f"{self.out} already holds a run", "pass --resume to continue it, or choose another --out")

    @property
    def iteration(self) -> int:
        return self.dagger_done + self.finetune_done

    @property
    def total_iterations(self) -> int:
        return self.cfg.iterations + self.cfg.finetune_iterations

    # ------------------------------------------------------------------ checkpoints
    def meta(self) -> CheckpointMeta:
        tm = self.teacher_meta
        lr = self.ppo.learning_rate if self.ppo is not None else self.optimizer.param_groups[0]["lr"]
        return CheckpointMeta(
            format=STUDENT_FORMAT, iteration=self.iteration, weights="model.safetensors", train=tm.train,
            model=tm.model, env=self.env.cfg, training_hands=self.training_hands, git_revision=self.git_revision,
            learning_rate=float(lr), reward_normalizer=NormalizerState(**self.reward_norm.state()),
            last=self.history[-1] if self.history else None,
            student=StudentMeta(distill=self.cfg, teacher_path=self.teacher_path,
                                teacher_weights_sha256=tm.weights_sha256, teacher_iteration=tm.iteration,
                                teacher_layout=tm.contract.observation, dagger_iterations=self.dagger_done,
                                finetune_iterations=self.finetune_done, init=self.init_stats))

    def save(self) -> None:
        if not all(bool(torch.isfinite(p).all()) for p in self.model.parameters()):
            raise DgzError(f"distillation diverged at iteration {self.iteration}: non-finite weights; not saved",
                           f"resume from the last checkpoint in {self.out} with a smaller --learning-rate")
        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        opt = self.ppo.optimizer_tensors() if self.ppo is not None else _adam_tensors(self.optimizer)
        tensors.update({f"optim.{k}": v for k, v in opt.items()})
        atomic_write_bytes(self.out / "history.jsonl", "".join(json.dumps(r) + "\n" for r in self.history).encode())
        checkpoint.save(self.out, tensors, self.meta())

    def _resume(self) -> None:
        tensors, meta = checkpoint.load(self.out)
        if meta.student is None:
            raise DgzError(f"{self.out}: holds a `dgz train` run, not a distillation", "choose another --out")
        if meta.model != self.model.cfg or meta.contract != self.env.cfg.contract or \
                meta.student.distill.student != self.cfg.student:
            raise DgzError(f"{self.out}: the checkpoint's student or control contract differs from the requested one",
                           "resume with the same --teacher and student options, or start a new --out")
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        self.dagger_done, self.finetune_done = meta.student.dagger_iterations, meta.student.finetune_iterations
        self.init_stats = meta.student.init
        optim = {k[6:]: v for k, v in tensors.items() if k.startswith("optim.")}
        if self.finetune_done > 0:
            self._start_ppo()
            self.ppo.load_optimizer_tensors(optim, meta.learning_rate)
        elif optim:
            _load_adam(self.optimizer, optim, meta.learning_rate)
        if meta.reward_normalizer is not None:
            self.reward_norm.load(meta.reward_normalizer.model_dump())
        hist = self.out / "history.jsonl"
        if hist.exists() or hist.is_symlink():
            from dgz_cli.rl.history import read_history

            self.history = read_history(hist, self.iteration)
        torch.manual_seed(self.cfg.seed + self.iteration)

    # ------------------------------------------------------------------ loop
    def run(self) -> None:
        cfg = self.cfg
        try:
            self.obs = self.env.reset(cfg.seed + self.iteration)
            self.hist.reset()
            while self.dagger_done < cfg.iterations:
                self.dagger_iteration()
                if self.iteration % cfg.checkpoint_every == 0 or self.dagger_done == cfg.iterations:
                    self.save()
            while self.finetune_done < cfg.finetune_iterations:
                self.finetune_iteration()
                if self.iteration % cfg.checkpoint_every == 0 or self.iteration == self.total_iterations:
                    self.save()
        except KeyboardInterrupt:
            self.save()
            raise
        finally:
            self.env.close()

    def _student_inputs(self, obs: dict) -> dict[str, torch.Tensor]:
        """This step's observation tensors with the history (its token pushed first)."""
        obs_t = to_tensors(obs)
        tok = tokens(obs["nodes"], obs["global"], obs["node_valid"], self.env.cfg.contract.observation)
        return student_obs(obs_t, self.hist.push(tok))

    def dagger_iteration(self) -> dict:
        """Roll out the student, label with the teacher, aggregate, fit; returns (and logs) the history row."""
        cfg, env, t0 = self.cfg, self.env, time.perf_counter()
        torch.set_num_threads(1)
        self.model.eval()
        nodes, glob, hists, labels, executed = [], [], [], [], []
        episodes: list[dict] = []
        first = to_tensors(self.obs)
        static = {k: first[k].clone() for k in STATIC_KEYS}
        obs = self.obs
        with torch.no_grad():
            for _ in range(cfg.steps_per_env):
                self.stop.check()
                s_in = self._student_inputs(obs)
                a = self.model.act(s_in)
                label = self.teacher.act(to_tensors(env.teacher_obs))
                nodes.append(s_in["nodes"])
                glob.append(s_in["global"])
                hists.append(s_in["history"])
                labels.append(label)
                executed.append(a)
                obs, _, terminated, truncated, info = env.step(a.numpy())
                done = terminated | truncated
                if done.any():
                    self.hist.reset(done)
                episodes += list(info["episode"].values())
        self.obs = obs
        collect_s = time.perf_counter() - t0
        data = dict(nodes=torch.stack(nodes), global_=torch.stack(glob), history=torch.stack(hists),
                    labels=torch.stack(labels), static=static)
        av = self.model.action_valid({**static, "nodes": nodes[0]}).float()  # (B, A): the same every step
        on_policy = float((((torch.stack(executed) - data["labels"]) ** 2) * av).sum() / (av.sum() * len(nodes)))
        self.buffer = (self.buffer + [data])[-cfg.buffer_iterations:]
        tf = time.perf_counter()
        torch.set_num_threads(cfg.torch_threads)
        first_mse, last_mse = self.fit()
        self.dagger_done += 1
        wall = time.perf_counter() - t0
        row = dict(iteration=self.iteration, dagger=1, wall_s=round(wall, 2), collect_s=round(collect_s, 2),
                   fit_s=round(time.perf_counter() - tf, 2),
                   steps_per_s=round(cfg.steps_per_env * env.B / collect_s, 1), episodes=len(episodes),
                   success_rate=float(np.mean([e["success"] for e in episodes])) if episodes else None,
                   mean_return=float(np.mean([e["return_"] for e in episodes])) if episodes else None,
                   imitation_mse=on_policy, bc_loss_first_epoch=first_mse, bc_loss=last_mse,
                   samples=sum(d["labels"].shape[0] * d["labels"].shape[1] for d in self.buffer),
                   learning_rate=float(self.optimizer.param_groups[0]["lr"]))
        self.history.append(row)
        self.log(row)
        return row

    def fit(self) -> tuple[float, float]:
        """``epochs`` passes of MSE regression over the buffer; returns the first and last epoch's mean loss."""
        cfg, model = self.cfg, self.model
        model.train()
        sizes = [d["labels"].shape[0] * d["labels"].shape[1] for d in self.buffer]
        total = sum(sizes)
        starts = np.cumsum([0] + sizes)
        losses = []
        for _ in range(cfg.epochs):
            perm = torch.randperm(total, generator=self.gen)
            acc, n = 0.0, 0
            for k in range(0, total, cfg.mini_batch):
                self.stop.check()
                idx = perm[k:k + cfg.mini_batch]
                obs, target = self._batch(idx, starts)
                mean = model(obs)[0]
                av = model.action_valid(obs).float()
                loss = (((mean - target) ** 2) * av).sum() / av.sum()
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm)
                self.optimizer.step()
                acc += float(loss.detach()) * len(idx)
                n += len(idx)
            losses.append(acc / max(1, n))
        model.eval()
        return losses[0], losses[-1]

    def _batch(self, idx: torch.Tensor, starts: np.ndarray) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Observations (with history) and teacher labels of flat sample indices over the buffer."""
        parts_obs, parts_y = [], []
        which = np.searchsorted(starts, idx.numpy(), side="right") - 1
        for j in np.unique(which):
            d = self.buffer[int(j)]
            local = idx[torch.as_tensor(which == j)] - int(starts[j])
            b_count = d["labels"].shape[1]
            t, b = local // b_count, local % b_count
            parts_obs.append({**{k: v[b] for k, v in d["static"].items()}, "nodes": d["nodes"][t, b],
                              "global": d["global_"][t, b], "history": d["history"][t, b]})
            parts_y.append(d["labels"][t, b])
        obs = {k: torch.cat([p[k] for p in parts_obs]) for k in parts_obs[0]}
        return obs, torch.cat(parts_y)

    # ------------------------------------------------------------------ PPO fine-tuning
    def _start_ppo(self) -> None:
        if self.ppo is None:
            self.ppo = PPO(self.model, self.teacher_meta.train.ppo)
            self.ppo.set_learning_rate(self.cfg.finetune_learning_rate)

    def finetune_iteration(self) -> dict:
        """One PPO iteration of the student (rollout with sampled actions, then the update)."""
        cfg, env, t0 = self.cfg, self.env, time.perf_counter()
        self._start_ppo()
        torch.set_num_threads(1)
        self.model.eval()
        steps = cfg.finetune_steps_per_env
        episodes: list[dict] = []
        obs = self.obs
        for _ in range(steps):
            self.stop.check()
            s_in = self._student_inputs(obs)
            out = self.ppo.act(s_in)
            if self.storage is None:
                self.storage = RolloutStorage(steps, env.B, s_in, env.action_dim, seed=cfg.seed)
            obs, reward, terminated, truncated, info = env.step(out["action"].numpy())
            done = terminated | truncated
            scaled = self.reward_norm(reward.astype(np.float64), done)
            self.storage.add(s_in, reward=scaled, terminated=terminated, truncated=truncated, **out)
            if done.any():
                self.hist.reset(done)
            episodes += list(info["episode"].values())
        self.obs = obs
        with torch.no_grad():  # V(s_T) from the next step's inputs, without advancing the history
            saved = self.hist.buf.copy()
            last_value = self.ppo.value(self._student_inputs(obs))
            self.hist.buf[:] = saved
        tu = time.perf_counter()
        torch.set_num_threads(cfg.torch_threads)
        stats = self.ppo.update(self.storage, last_value)
        self.finetune_done += 1
        wall = time.perf_counter() - t0
        row = dict(iteration=self.iteration, dagger=0, wall_s=round(wall, 2), ppo_update_s=round(time.perf_counter() - tu, 2),
                   steps_per_s=round(steps * env.B / wall, 1), episodes=len(episodes),
                   success_rate=float(np.mean([e["success"] for e in episodes])) if episodes else None,
                   mean_return=float(np.mean([e["return_"] for e in episodes])) if episodes else None,
                   learning_rate=float(self.ppo.learning_rate),
                   **{k: float(v) for k, v in stats.items() if k != "learning_rate"})
        self.history.append(row)
        self.log(row)
        return row


def _adam_tensors(opt: torch.optim.Adam) -> dict[str, torch.Tensor]:
    st = opt.state_dict()["state"]
    return {f"{i}.{k}": torch.as_tensor(v) for i, s in st.items() for k, v in s.items()}


def _load_adam(opt: torch.optim.Adam, tensors: dict[str, torch.Tensor], lr: float) -> None:
    sd = opt.state_dict()
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, v in tensors.items():
        i, name = key.split(".", 1)
        state.setdefault(int(i), {})[name] = v
    opt.load_state_dict({"state": state, "param_groups": sd["param_groups"]})
    for g in opt.param_groups:
        g["lr"] = lr
