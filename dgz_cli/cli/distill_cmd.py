"""`dgz distill`: a privileged teacher → a student that runs on what hardware gives (issue 12). The composition
root of distillation: it loads the teacher, builds the env under the hardware view and hands both to
:class:`dgz_cli.rl.distill.Distiller`; progress lines, TensorBoard, curve, atomic checkpoints, ``--resume``
and SIGTERM/SIGHUP behave as in ``dgz train`` (:mod:`dgz_cli.cli.train_cmd`)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.markup import escape


# The options whose CLI name is not their DistillConfig field's (hyphens aside); used both ways.
_FIELD_OF_OPTION = {"steps": "steps_per_env", "settle": "settle_s"}
# The options that set a field of a nested DistillConfig section (the field has the option's name).
_SECTION_OPTIONS = {"view": ("joint_noise", "held_cloud"), "student": ("history",)}


def _load_config(given: dict, out: Path, resume: bool):
    """DistillConfig from its defaults, the run's own record when resuming, and the options given
    (keyed by CLI option name, underscores for hyphens)."""
    from pydantic import ValidationError

    from dgz_cli.rl.distill_config import DistillConfig
    from dgz_cli.spec.errors import DgzError

    given = {_FIELD_OF_OPTION.get(k, k): v for k, v in given.items()}
    base: dict = {}
    if resume and (out / "checkpoint.yaml").is_file():
        from dgz_cli.rl.checkpoint import read_meta

        meta = read_meta(out)
        if meta.student is None:
            raise DgzError(f"--out {out}: holds a `dgz train` run, not a distillation", "choose another --out")
        base = meta.student.distill.model_dump()
    for section, keys in _SECTION_OPTIONS.items():
        fields = dict(base.get(section) or {})
        for key in keys:
            if key in given:
                fields[key] = given.pop(key)
        if fields:
            base[section] = fields
    base.update(given)
    if "teacher" not in base:
        from dgz_cli.spec.errors import DgzError

        raise DgzError("no --teacher given", "name the teacher checkpoint, e.g. --teacher dgz-cpu-warmstart")
    try:
        return DistillConfig(**base)
    except ValidationError as exc:
        e = exc.errors()[0]
        name = e["loc"][-1] if e["loc"] and e["loc"][0] in _SECTION_OPTIONS else ".".join(map(str, e["loc"]))
        option = {f: o for o, f in _FIELD_OF_OPTION.items()}.get(str(name), str(name)).replace("_", "-")
        raise DgzError(f"--{option}: {e['msg']}", "see `dgz distill --help` and docs/distill.md") from None


def build(cfg, out: Path, asset_root: str | None, resume: bool = False, log=None):
    """Teacher, specs, objects and the hardware-view env from ``cfg`` (a DistillConfig), then the Distiller.
    Bad input fails here, before anything is written."""
    from dgz_cli.rl.checkpoint import LoadedPolicy, resolve_checkpoint, spec_hash
    from dgz_cli.spec.catalog import policies_dir
    from dgz_cli.rl.distill import Distiller
    from dgz_cli.sim.hardware import HardwareViewEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.cli.hand_refs import hand_specs
    from dgz_cli.spec.catalog import policy_ref
    from dgz_cli.spec.errors import DgzError
    from dgz_cli.spec.hardware_view import student_contract
    from dgz_cli.spec.io import load_spec

    directory = resolve_checkpoint(policy_ref(cfg.teacher))
    if directory is None:
        raise DgzError(f"--teacher {cfg.teacher!r}: no such checkpoint folder or name under policies/",
                       "name a run directory written by `dgz train` or a shipped policy, e.g. dgz-cpu-warmstart")
    teacher = LoadedPolicy(directory)
    if teacher.meta.student is not None:
        raise DgzError(f"--teacher {cfg.teacher}: is a distilled student", "distil from a `dgz train` checkpoint")
    spec_paths = hand_specs(cfg.hands, asset_root)  # shipped names, spec paths and generated:DIR, as `dgz train`
    specs = [load_spec(p) for p in spec_paths.values()]
    objs = resolve_objects(cfg.objects, asset_root)
    pairs = [(s, o) for _ in range(cfg.repeat) for s in specs for o in objs]
    tmeta = teacher.meta
    env_cfg = tmeta.env.model_copy(update=dict(contract=student_contract(tmeta.contract))
                                   | ({} if cfg.settle_s is None else dict(settle_s=cfg.settle_s)))
    env = HardwareViewEnv(pairs, env_cfg, cfg.view, teacher_layout=tmeta.contract.observation,
                          teacher_sees_view=cfg.teacher_view == "student", seed=cfg.seed,
                          asset_root=asset_root, threads=cfg.threads, use_pen=tmeta.train.ablation != "no_mask")
    try:
        shipped = Path(directory).resolve().parent == policies_dir().resolve()
        return Distiller(cfg, env, teacher.model, tmeta, cfg.teacher if shipped else str(directory), out,
                         {s.name: spec_hash(p) for s, p in zip(specs, spec_paths.values())}, resume=resume, log=log)
    except BaseException:
        env.close()
        raise


def run(given: dict, out: Path, resume: bool, asset_root: str | None, console: Console) -> int:
    from dgz_cli.cli.train_cmd import _check_out, log_scalars, open_run, run_until_stopped
    from dgz_cli.rl.runner import write_csv, write_curve

    existed = _check_out(out)
    cfg = _load_config(dict(given), out, resume)
    dist = build(cfg, out, asset_root, resume, log=lambda row: log(row))
    writer, tb_before = open_run(out, existed, dist.env)

    def log(row: dict) -> None:
        log_scalars(writer, row)
        sr = "—" if row["success_rate"] is None else f"{row['success_rate']:.3f}"
        if row["dagger"]:
            what = (f"DAgger  imitation MSE {row['imitation_mse']:.4f}  fit {row['bc_loss_first_epoch']:.4f} → "
                    f"{row['bc_loss']:.4f} on {row['samples']} samples  [dim]collect {row['collect_s']}s "
                    f"fit {row['fit_s']}s[/]")
        else:
            what = f"PPO  kl {row.get('kl', 0):.4f} lr {row.get('learning_rate', 0):.1e}  [dim]upd {row['ppo_update_s']}s[/]"
        console.print(f"it {row['iteration']:4d}/{dist.total_iterations}  {row['steps_per_s']:7.0f} steps/s  "
                      f"student success {sr}  {what}", highlight=False)
        hist = [dict(h, mean_return=h.get("mean_return")) for h in dist.history]
        write_curve(hist, out / "curve.png")
        write_csv([{k: h.get(k) for k in _COLUMNS} for h in dist.history], out / "history.csv")

    init = dist.init_stats or {}
    console.print(f"distilling {escape(str(cfg.teacher))} into a student (LSTM {cfg.student.lstm_hidden} over "
                  f"{cfg.student.history} steps) on {escape(', '.join(cfg.hands))} × {escape(str(cfg.objects))}: "
                  f"{dist.env.B} envs, {cfg.steps_per_env} steps per DAgger iteration, from iteration {dist.iteration}; "
                  f"hardware view: {escape(cfg.view.describe())}; from the teacher: {init.get('copied', 0)} tensors "
                  f"copied, {init.get('partial', 0)} partly, {init.get('fresh', 0)} new", highlight=False)
    if not run_until_stopped(dist.run, dist.stop, out, existed, tb_before, writer):
        console.print(f"[yellow]interrupted: saved iteration {dist.iteration} to {escape(str(out))}[/] "
                      "(continue with --resume)")
        return 130
    console.print(f"[green]wrote[/] {escape(str(out))} ({dist.iteration} iterations); evaluate it with "
                  f"`dgz eval --policy {escape(str(out))} --hand ...`", highlight=False)
    return 0


_COLUMNS = ("iteration", "dagger", "wall_s", "collect_s", "fit_s", "ppo_update_s", "steps_per_s", "episodes",
            "success_rate", "mean_return", "imitation_mse", "bc_loss_first_epoch", "bc_loss", "samples", "kl",
            "learning_rate")
