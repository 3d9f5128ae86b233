"""`dgz scene` and `dgz eval` (the simulation protocol)."""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.markup import escape
from rich.table import Table

from dgz_cli.spec.errors import DgzError


def scene(hand: str, obj: str, out: Path, asset_root: str | None, console: Console) -> int:
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.sim.scene import write_scene_xml
    from dgz_cli.spec.envconfig import EnvConfig
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    objects = resolve_objects(obj, asset_root)
    if len(objects) != 1:
        raise DgzError(f"--object '{obj}' names {len(objects)} objects", "give exactly one object name")
    write_scene_xml(load_spec(resolve_spec(hand)), objects[0], EnvConfig(), asset_root, out)
    console.print(f"[green]wrote[/] {escape(str(out))} [dim](view it: python -m mujoco.viewer --mjcf "
                  f"{escape(str(out))})[/]")
    return 0


def evaluate(policy: str, hands: list[str], objects: str, trials: int, seed: int, zero_shot: bool,
             json_out: Path | None, csv_out: Path | None, asset_root: str | None, console: Console, *,
             guidance: float = 0.0, guidance_stop_gap: float | None = None, roll: str | None = None,
             video: Path | None = None, video_episodes: int = 2,
             perturb: bool = True, feature_scale: float = 1.0, approach_cone: float | None = None,
             physics_hz: float | None = None, thumb_open: float | None = None, settle: float | None = None,
             object_orientation: str | None = None) -> int:
    from dgz_cli.cli.hand_refs import hand_specs
    from dgz_cli.sim.evaluate import CSV_COLUMNS, csv_row, hand_reports, run_episodes, summarize
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.envconfig import EnvConfig
    from dgz_cli.spec.io import atomic_write, check_output, load_spec
    from dgz_cli.spec.transform import scale_lengths

    import os

    for option, target in (("--json", json_out), ("--csv", csv_out)):  # refused before the evaluation runs
        if target is not None:
            check_output(target, option)
    if json_out is not None and csv_out is not None and os.path.realpath(json_out) == os.path.realpath(csv_out):
        raise DgzError(f"--json and --csv name the same file {json_out}", "give them different paths")
    if video is not None:
        video = _video_dir(video, console)  # None (with a one-line note) where nothing can render
    make_policy, meta = _policy_factory(policy)
    # the URDF-prior sensitivity test: link lengths scaled in the policy's physical features only
    spec_paths = list(hand_specs(hands, asset_root, "--hand").values())  # names, spec files and generated:DIR
    specs = [scale_lengths(load_spec(p), feature_scale) for p in spec_paths]
    if meta is None and feature_scale != 1.0:
        console.print("[yellow]note:[/] --feature-scale changes only the policy's physical features, which the "
                      "scripted policy does not read")
    if zero_shot:
        if meta is None:
            raise DgzError("--zero-shot needs a trained policy's list of training hands",
                           "drop --zero-shot for --policy scripted")
        seen = sorted(set(meta.training_hands) & {s.name for s in specs})
        if seen:
            raise DgzError(f"--zero-shot: {', '.join(seen)} {'was' if len(seen) == 1 else 'were'} a training hand of "
                           f"{policy}", "drop --zero-shot to evaluate seen hands, or pick unseen ones")
    if meta is not None and (guidance != 0.0 or guidance_stop_gap is not None or physics_hz is not None
                             or thumb_open is not None):
        raise DgzError("--guidance, --guidance-stop-gap, --physics-hz and --thumb-open set the scripted policy's "
                       "env; a checkpoint runs under its own",
                       "drop --guidance/--guidance-stop-gap/--physics-hz/--thumb-open")
    if guidance_stop_gap is not None and guidance == 0.0:
        raise DgzError("--guidance-stop-gap without --guidance: the guidance is off", "add e.g. --guidance 0.05")
    if roll is not None and roll not in ("uniform", "narrow", "clear"):
        raise DgzError(f"--roll {roll!r} is not supported", "use --roll uniform, narrow or clear")
    if meta is not None:
        cfg = meta.env  # a policy is evaluated under the contract it was trained with
    else:
        from pydantic import ValidationError

        from dgz_cli.rl.config import TrainConfig, env_config

        # the scripted env is the one `dgz train` would build for the same options (one home: env_config)
        options = (dict(guidance_gain=guidance, roll=roll or "uniform")
                   | ({} if guidance_stop_gap is None else dict(guidance_stop_gap=guidance_stop_gap))
                   | ({} if physics_hz is None else dict(physics_hz=physics_hz))
                   | ({} if thumb_open is None else dict(thumb_open=thumb_open)))
        try:
            cfg = env_config(TrainConfig(**options))
        except ValidationError as exc:
            error = exc.errors()[0]
            option, value, example = {"guidance_gain": ("--guidance", guidance, "0.05"),
                                      "guidance_stop_gap": ("--guidance-stop-gap", guidance_stop_gap, "0.05"),
                                      "physics_hz": ("--physics-hz", physics_hz, "200"),
                                      "thumb_open": ("--thumb-open", thumb_open, "1")}.get(
                error["loc"][0], ("--roll", roll, "narrow"))
            raise DgzError(f"{option} {value}: {error['msg'].removeprefix('Value error, ')}",
                           f"e.g. {option} {example}") from None
    if approach_cone is not None:  # the start state, a protocol choice: it applies to a checkpoint too
        cfg = cfg.model_copy(update=dict(approach_cone=approach_cone))
    if roll is not None and meta is not None:  # so does the start roll
        cfg = cfg.model_copy(update=dict(roll=roll))
    if settle is not None:  # and how long the object settles before the first frame
        cfg = cfg.model_copy(update=dict(settle_s=settle))
    if object_orientation is not None:  # and how the object is dropped
        cfg = cfg.model_copy(update=dict(object_orientation=object_orientation))
    if meta is not None:
        from dgz_cli.rl.checkpoint import spec_hash

        for path, spec in zip(spec_paths, specs):
            old_hash = meta.training_hands.get(spec.name)
            if old_hash is not None and old_hash != spec_hash(path):
                console.print(f"[yellow]warning:[/] the spec of training hand {escape(spec.name)} changed since "
                              f"{escape(policy)} was trained")
    objs = resolve_objects(objects, asset_root)
    pairs = [(s, o) for s in specs for o in objs]
    # a distilled student observes what hardware gives, as recorded in its checkpoint (--no-perturb: the sim's)
    view = meta.student.distill.view if meta is not None and meta.student is not None and perturb else None
    if meta is not None and meta.student is not None:
        console.print(f"student of {escape(meta.student.teacher_path)}; hardware view: "
                      f"{escape(view.describe() if view is not None else 'none (--no-perturb)')}", highlight=False)
    t0 = time.perf_counter()
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=True) as bar:
        task = bar.add_task(f"{escape(policy)}: {len(specs)} hand(s) × {len(objs)} object(s) × {trials} trials",
                            total=len(pairs) * trials)
        records: list[dict] = []
        for spec in specs:  # one env per hand keeps memory flat (one scene per object, not per pair)
            before = len(records)
            records += run_episodes([(spec, o) for o in objs], make_policy, trials, cfg, seed, asset_root,
                                    progress=lambda done, total: bar.update(task, completed=before + done), view=view)
    summary = summarize(records, cfg.contract.episode.lift_height, cfg.contract.episode.success_fraction)
    ep = cfg.contract.episode
    protocol = dict(lift_height_m=ep.lift_height, hold_s=ep.hold_s, success_fraction=ep.success_fraction,
                    trials_per_object=trials, seed=seed, episode_steps=ep.episode_steps,
                    guidance_gain=cfg.contract.guidance.gain, guidance_stop_gap_m=cfg.contract.guidance.stop_gap,
                    roll=cfg.roll,
                    physics_hz=round(1.0 / ep.physics_dt, 6),
                    hardware_view=None if view is None else view.model_dump(), feature_scale=feature_scale,
                    approach_distance_m=cfg.approach_distance, approach_cone_rad=cfg.approach_cone,
                    settle_s=cfg.settle_s, object_orientation=cfg.object_orientation,
                    thumb_open=cfg.contract.start.thumb_open,
                    thumb_open_primitives=list(cfg.contract.start.thumb_primitives))
    table = Table(title=f"{escape(policy)} — success = object lifted {ep.lift_height} m (≥ {ep.success_fraction:.0%} "
                        f"kept) and held {ep.hold_s} s; {trials} trials per object, seed {seed}")
    table.add_column("hand")
    table.add_column("success rate", justify="right")
    table.add_column("episodes", justify="right")
    from dgz_cli.sim.evaluate import FAILURE_CLASSES

    for c in FAILURE_CLASSES:
        table.add_column(c, justify="right")
    table.add_column("rise ≥ 0.1 m (GraspXL)", justify="right")
    table.add_column("closing onset, palm → surface m", justify="right")
    for name, h in summary.items():
        onset = h["closing_onset_distance_m"]
        table.add_row(escape(name), f"{h['success_rate']:.3f}", str(h["episodes"]),
                      *(str(h["failures"][c]) for c in FAILURE_CLASSES), f"{h['graspxl_success_rate']:.3f}",
                      "—" if onset is None else f"{onset:.3f}")
    console.print(table)
    console.print(f"[dim]{len(records)} episodes in {time.perf_counter() - t0:.0f} s[/]")
    if json_out is not None:
        report = dict(policy=policy, protocol=protocol,
                      training_hands=sorted(meta.training_hands) if meta else [],
                      hands=hand_reports(summary))
        atomic_write(json_out, json.dumps(report, indent=2) + "\n")
    if csv_out is not None:
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(CSV_COLUMNS)
        for r in records:
            w.writerow(csv_row(r, cfg.contract.episode.lift_height, cfg.contract.episode.success_fraction))
        atomic_write(csv_out, buf.getvalue())
    if video is not None:
        from dgz_cli.sim.video import rollouts, write_videos

        with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), console=console,
                      transient=True) as bar:
            task = bar.add_task("rendering", total=len(specs) * video_episodes)
            eps = rollouts([(s, objs[0]) for s in specs], make_policy, video_episodes, cfg, seed, asset_root,
                           progress=lambda done, total: bar.update(task, completed=done))
        for path in write_videos(eps, video, cfg.contract.episode.control_hz):
            console.print(f"[green]wrote[/] {escape(str(path))}", highlight=False, soft_wrap=True)
    return 0


def _video_dir(video: Path, console: Console) -> Path | None:
    """``--video DIR`` made (before anything is evaluated), or None with a one-line note when this machine has
    no offscreen OpenGL backend (the evaluation still runs)."""
    from dgz_cli.sim.video import gl_problem, prepare_gl

    if video.exists() and not video.is_dir():
        raise DgzError(f"--video {video}: exists and is not a folder", "name a folder (it is created if missing)")
    try:
        video.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DgzError(f"--video {video}: cannot create the folder ({exc.strerror})", "name a writable folder") from None
    prepare_gl()
    problem = gl_problem()
    if problem is not None:
        console.print(f"[yellow]skipping --video:[/] {escape(problem)}", highlight=False, soft_wrap=True)
        return None
    return video


def _policy_factory(policy: str):
    """'scripted' → (factory, None); a checkpoint dir or a policies/ name → (factory, its CheckpointMeta)."""
    if policy == "scripted":
        from dgz_cli.sim.scripted import ScriptedGrasp

        return ScriptedGrasp.for_env, None
    from dgz_cli.rl.checkpoint import LoadedPolicy, resolve_checkpoint

    from dgz_cli.spec.catalog import policy_ref

    directory = resolve_checkpoint(policy_ref(policy))  # a shipped name resolves in a wheel install too
    if directory is None:
        raise DgzError(f"--policy {policy!r}: no such checkpoint folder or name under policies/",
                       "use 'scripted', a run directory written by `dgz train`, or a shipped policy name")
    loaded = LoadedPolicy(directory)
    return (lambda env: loaded), loaded.meta
