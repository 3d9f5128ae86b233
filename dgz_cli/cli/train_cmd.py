"""`dgz train`: multi-hand PPO with rich progress, TensorBoard, a live curve PNG and checkpoints."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table


def _load_config(given: dict, config_file: Path | None, out: Path, resume: bool):
    """TrainConfig from (in increasing priority) its defaults, the run's own record when resuming or the
    ``--init-from`` checkpoint's run config when fine-tuning, a ``--config`` YAML and the options given on
    the command line."""
    import yaml
    from pydantic import ValidationError

    from dgz_cli.rl.checkpoint import read_meta
    from dgz_cli.rl.config import TrainConfig
    from dgz_cli.spec.errors import DgzError

    data: dict = {}
    if config_file is not None:
        try:
            data = yaml.safe_load(config_file.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise DgzError(f"{config_file}: cannot read the run config ({' '.join(str(exc).split())})",
                           "give a YAML mapping of TrainConfig fields (see docs/training.md)") from None
        if not isinstance(data, dict):
            raise DgzError(f"{config_file}: the run config must be a YAML mapping", "see docs/training.md")
    base: dict = {}
    init_ref = given.get("init_from", data.get("init_from"))
    if resume and (out / "checkpoint.yaml").is_file():
        base = read_meta(out).train.model_dump()
    elif isinstance(init_ref, str) and init_ref:
        # fine-tuning keeps the checkpoint's recipe unless told otherwise; its own warm start is history
        base = read_meta(_init_directory(init_ref)).train.model_dump() | dict(bc_episodes=0)
    base.update(data)
    base.update(given)
    try:
        return TrainConfig(**base)
    except ValidationError as exc:
        e = exc.errors()[0]
        where = f"{config_file}: " if config_file is not None and e["loc"] and e["loc"][0] not in given else ""
        field = ".".join(map(str, e["loc"])).replace("_", "-")
        raise DgzError(f"{where}{'--' + field if field else 'run config'}: {e['msg']}",
                       "see `dgz train --help` and docs/training.md") from None


def _init_directory(ref: str) -> Path:
    """The checkpoint folder ``--init-from`` names: a folder or a shipped policy."""
    from dgz_cli.rl.checkpoint import resolve_checkpoint
    from dgz_cli.spec.catalog import policy_ref
    from dgz_cli.spec.errors import DgzError

    directory = resolve_checkpoint(policy_ref(ref))
    if directory is None:
        raise DgzError(f"--init-from {ref!r}: no such checkpoint folder or name under policies/",
                       "name a run directory written by `dgz train` or a shipped policy, e.g. dgz-cpu-thumb-open")
    return directory


def build(cfg, out: Path, asset_root: str | None, resume: bool = False, log=None, on_warm_start=None):
    """The composition root of training: specs, objects and the env from ``cfg`` (a TrainConfig), then the
    Trainer that receives them. Bad input fails here, before anything is written."""
    from dgz_cli.cli.hand_refs import hand_specs
    from dgz_cli.policy.presets import PRESETS
    from dgz_cli.rl import checkpoint
    from dgz_cli.rl.checkpoint import spec_hash
    from dgz_cli.rl.config import env_config
    from dgz_cli.rl.runner import Trainer
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.sim.scripted import ScriptedGrasp
    from dgz_cli.spec.errors import DgzError
    from dgz_cli.spec.io import load_spec

    if cfg.preset not in PRESETS:
        raise DgzError(f"--preset '{cfg.preset}' is not a MAGCN preset", f"choose one of: {', '.join(sorted(PRESETS))}")
    spec_paths = hand_specs(cfg.hands, asset_root)
    specs = [load_spec(p) for p in spec_paths.values()]
    objs = resolve_objects(cfg.objects, asset_root)
    pairs = [(s, o) for _ in range(cfg.repeat) for s in specs for o in objs]
    init = None if resume or cfg.init_from is None else (*checkpoint.load(_init_directory(cfg.init_from)), cfg.init_from)
    kwargs = dict(seed=cfg.seed, asset_root=asset_root, threads=cfg.threads, use_pen=cfg.ablation != "no_mask")
    if cfg.observed_view is not None:
        from dgz_cli.sim.hardware import HardwareViewEnv

        env = HardwareViewEnv(pairs, env_config(cfg), cfg.observed_view, **kwargs)
    else:
        env = GraspEnv(pairs, env_config(cfg), **kwargs)
    try:
        return Trainer(cfg, env, out, {s.name: spec_hash(p) for s, p in zip(specs, spec_paths.values())},
                       resume=resume, log=log, on_warm_start=on_warm_start,
                       teacher_factory=ScriptedGrasp.for_env, init=init)
    except BaseException:
        env.close()
        raise


def _check_out(out: Path) -> bool:
    """Refuse an unusable --out before anything is built; True when it already exists (a folder)."""
    import os
    import stat

    from dgz_cli.spec.errors import DgzError

    try:
        st = os.stat(out)
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise DgzError(f"--out {out}: {exc.strerror or exc}", "choose a writable --out folder") from None
    if not stat.S_ISDIR(st.st_mode):
        raise DgzError(f"--out {out}: exists and is not a folder", "--out names the run folder; choose another path")
    return True


def _clean_failed_run(out: Path, existed: bool, tb_before: set) -> None:
    """Remove what a failed run created: its new TensorBoard event files, and the folders it made if empty."""
    import shutil

    if not existed:  # the folder is this run's own
        shutil.rmtree(out, ignore_errors=True)
        return
    tb = out / "tb"
    for f in set(tb.glob("*")) - tb_before if tb.is_dir() else ():
        shutil.rmtree(f, ignore_errors=True) if f.is_dir() else f.unlink(missing_ok=True)
    try:
        tb.rmdir()  # only when empty
    except OSError:
        pass


def _mtime(path: Path):
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


def run(given: dict, config_file: Path | None, out: Path, resume: bool, asset_root: str | None, console: Console) -> int:
    from dgz_cli.rl.runner import write_csv, write_curve

    existed = _check_out(out)
    cfg = _load_config(given, config_file, out, resume)
    trainer = build(cfg, out, asset_root, resume, log=lambda row: log(row), on_warm_start=lambda stats: warm(stats))
    writer, tb_before = open_run(out, existed, trainer.env)  # only now: a run refused on its input leaves nothing

    def log(row: dict) -> None:
        log_scalars(writer, row)
        sr = "—" if row["success_rate"] is None else f"{row['success_rate']:.3f}"
        terms = " ".join(f"{k[2:]} {v:.2f}" for k, v in row.items() if k.startswith("r_") and v is not None)
        console.print(f"it {row['iteration']:4d}/{cfg.iterations}  {row['steps_per_s']:7.0f} steps/s  success {sr}  "
                      f"return {row['mean_return'] if row['mean_return'] is None else round(row['mean_return'], 1)}  "
                      f"{terms}  [dim]phys {row['physics_s']:.2f}s env {row['env_other_s']:.2f}s "
                      f"fwd {row['policy_forward_s']:.2f}s upd {row['ppo_update_s']:.2f}s kl {row.get('kl', 0):.4f} lr {row.get('learning_rate', 0):.1e}[/]",
                      highlight=False)
        write_curve(trainer.history, out / "curve.png")
        write_csv(trainer.history, out / "history.csv")

    def warm(stats: dict) -> None:
        console.print(f"behaviour cloning from the scripted grasp: {stats['episodes']} episodes "
                      f"(teacher success {stats['teacher_success_rate']:.3f}, clone success per DAgger round "
                      f"{stats['clone_success_rates']}), action MSE {stats['bc_action_loss']:.4f}, "
                      f"value MSE {stats['bc_value_loss']:.3f} [dim]collect {stats['collect_s']}s fit {stats['fit_s']}s[/]",
                      highlight=False)

    start = (f"from {escape(cfg.init_from)}'s weights (its iteration {trainer.warm_start['checkpoint_iteration']})"
             if trainer.iteration == 0 and cfg.init_from is not None else f"from iteration {trainer.iteration}")
    console.print(f"training {cfg.preset} ({cfg.ablation}) on {escape(', '.join(cfg.hands))} × {escape(str(cfg.objects))}: "
                  f"{trainer.env.B} envs, {cfg.steps_per_env} steps per update, {start}")
    if cfg.observed_view is not None:
        console.print(f"observing the object as hardware gives it: {escape(cfg.observed_view.describe())}; contact and "
                      "force as in simulation", highlight=False)
    if not run_until_stopped(trainer.train, trainer.stop, out, existed, tb_before, writer):
        console.print(f"[yellow]interrupted: saved iteration {trainer.iteration} to {escape(str(out))}[/] "
                      "(continue with --resume)")
        return 130
    table = Table(title=f"{escape(str(out))}: {trainer.iteration} iterations")
    for col in ("iteration", "success_rate", "mean_return", "steps_per_s"):
        table.add_column(col)
    for row in trainer.history[-5:]:
        table.add_row(*(str(row[c] if row[c] is None or isinstance(row[c], int) else round(row[c], 3)) for c in
                        ("iteration", "success_rate", "mean_return", "steps_per_s")))
    console.print(table)
    return 0



def open_run(out: Path, existed: bool, env):
    """The run folder and its TensorBoard writer, created only once the run's input was accepted (``env``, the
    built env, is closed if that fails). Returns (writer, the tb files that were there before)."""
    from torch.utils.tensorboard import SummaryWriter

    tb_before = set((out / "tb").glob("*")) if (out / "tb").is_dir() else set()
    try:
        out.mkdir(parents=True, exist_ok=True)
        return SummaryWriter(log_dir=str(out / "tb")), tb_before
    except OSError as exc:
        env.close()
        if not existed:
            _clean_failed_run(out, existed, tb_before)
        from dgz_cli.spec.errors import DgzError

        raise DgzError(f"--out {out}: cannot create the run folder ({exc.strerror or exc})",
                       "choose a writable --out folder") from None


def log_scalars(writer, row: dict) -> None:
    """Every numeric field of a history row to TensorBoard at its iteration."""
    for k, v in row.items():
        if isinstance(v, (int, float)) and v is not None and k != "iteration":
            writer.add_scalar(k, v, row["iteration"])
    writer.flush()


def run_until_stopped(job, stop, out: Path, existed: bool, tb_before: set, writer) -> bool:
    """Run ``job()``; the first Ctrl-C, SIGTERM or SIGHUP (a closed terminal) only sets ``stop`` (the job's
    :class:`dgz_cli.rl.stop.StopRequest`), which the job turns into KeyboardInterrupt at its next step and saves
    on; a second one raises KeyboardInterrupt at once. Returns False when interrupted. A job that fails before
    its first checkpoint leaves nothing behind; the writer is closed and the previous signal handlers restored
    in every case."""
    from dgz_cli.runtime.rate import InterruptGuard  # the deploy loop's two-stage guard

    saved = _mtime(out / "checkpoint.yaml")
    try:
        with InterruptGuard(on_first=stop.request):
            job()
    except KeyboardInterrupt:
        return False
    except BaseException:
        writer.close()
        if _mtime(out / "checkpoint.yaml") == saved:  # failed before a checkpoint: leave nothing behind
            _clean_failed_run(out, existed, tb_before)
        raise
    finally:
        writer.close()
    return True

def bench(given: dict, config_file: Path | None, iterations: int, asset_root: str | None) -> dict:
    """`dgz bench train`: the Trainer that `dgz train` would build from the same options, run for
    ``iterations`` iterations into a throw-away folder (see :mod:`dgz_cli.bench.train_bench`)."""
    import tempfile

    from dgz_cli.bench import train_bench

    with tempfile.TemporaryDirectory(prefix="dgz-bench-train-") as tmp:
        out = Path(tmp) / "run"
        cfg = _load_config({**given, "iterations": iterations}, config_file, out, False)
        return train_bench.measure(build(cfg, out, asset_root), iterations)
