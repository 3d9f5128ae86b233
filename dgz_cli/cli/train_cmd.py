"""`dgz train`: multi-hand PPO with rich progress, TensorBoard, a live curve PNG and checkpoints."""

from __future__ import annotations

import signal
from pathlib import Path

from rich.console import Console
from rich.table import Table


def run(cfg_kwargs: dict, out: Path, resume: bool, asset_root: str | None, console: Console) -> int:
    from torch.utils.tensorboard import SummaryWriter

    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.rl.runner import Trainer, write_csv, write_curve

    from pydantic import ValidationError

    from dgz_cli.policy.presets import PRESETS
    from dgz_cli.spec.errors import DgzError

    try:
        cfg = TrainConfig(**cfg_kwargs)
    except ValidationError as exc:
        e = exc.errors()[0]
        raise DgzError(f"--{'.'.join(map(str, e['loc'])).replace('_', '-')}: {e['msg']}", "see `dgz train --help`") from None
    if cfg.preset not in PRESETS:
        raise DgzError(f"--preset '{cfg.preset}' is not a MAGCN preset", f"choose one of: {', '.join(sorted(PRESETS))}")
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec

    for h in cfg.hands:  # fail on bad input before anything is created
        resolve_spec(h)
    resolve_objects(cfg.objects, asset_root)
    out.mkdir(parents=True, exist_ok=True)
    writer = SummaryWriter(log_dir=str(out / "tb"))

    def log(row: dict) -> None:
        for k, v in row.items():
            if isinstance(v, (int, float)) and v is not None and k != "iteration":
                writer.add_scalar(k, v, row["iteration"])
        writer.flush()
        sr = "—" if row["success_rate"] is None else f"{row['success_rate']:.3f}"
        terms = " ".join(f"{k[2:]} {row[k]:.2f}" for k in ("r_dis", "r_contact", "r_force", "r_reg", "r_pen", "r_lift")
                         if row.get(k) is not None)
        console.print(f"it {row['iteration']:4d}/{cfg.iterations}  {row['steps_per_s']:7.0f} steps/s  success {sr}  "
                      f"return {row['mean_return'] if row['mean_return'] is None else round(row['mean_return'], 1)}  "
                      f"{terms}  [dim]phys {row['physics_s']}s env {row['env_other_s']}s fwd {row['policy_forward_s']}s "
                      f"upd {row['ppo_update_s']}s kl {row.get('kl', 0):.4f} lr {row.get('learning_rate', 0):.1e}[/]",
                      highlight=False)
        write_curve(trainer.history, out / "curve.png")
        write_csv(trainer.history, out / "history.csv")

    def warm(stats: dict) -> None:
        console.print(f"behaviour cloning from the scripted grasp: {stats['episodes']} episodes "
                      f"(teacher success {stats['teacher_success_rate']:.3f}, clone success per DAgger round "
                      f"{stats['clone_success_rates']}), action MSE {stats['bc_action_loss']:.4f}, "
                      f"value MSE {stats['bc_value_loss']:.3f} [dim]collect {stats['collect_s']}s fit {stats['fit_s']}s[/]",
                      highlight=False)

    trainer = Trainer(cfg, out, asset_root, resume=resume, log=log, on_warm_start=warm)
    console.print(f"training {cfg.preset} ({cfg.ablation}) on {', '.join(cfg.hands)} × {cfg.objects}: "
                  f"{trainer.env.B} envs, {cfg.steps_per_env} steps per update, from iteration {trainer.iteration}")
    previous = signal.getsignal(signal.SIGTERM)
    def _stop(*_) -> None:  # SIGTERM saves and exits like Ctrl-C
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _stop)
    try:
        trainer.train()
    except KeyboardInterrupt:
        console.print(f"[yellow]interrupted: saved iteration {trainer.iteration} to {out}[/] (continue with --resume)")
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        writer.close()
    table = Table(title=f"{out}: {trainer.iteration} iterations")
    for col in ("iteration", "success_rate", "mean_return", "steps_per_s"):
        table.add_column(col)
    for row in trainer.history[-5:]:
        table.add_row(*(str(row[c] if row[c] is None or isinstance(row[c], int) else round(row[c], 3)) for c in
                        ("iteration", "success_rate", "mean_return", "steps_per_s")))
    console.print(table)
    return 0
