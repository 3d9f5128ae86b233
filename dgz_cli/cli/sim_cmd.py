"""`dgz scene` and `dgz eval` (the simulation protocol)."""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table

from dgz_cli.spec.errors import DgzError


def scene(hand: str, obj: str, out: Path, asset_root: str | None, console: Console) -> int:
    from dgz_cli.sim.config import EnvConfig
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.sim.scene import write_scene_xml
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    objects = resolve_objects(obj, asset_root)
    if len(objects) != 1:
        raise DgzError(f"--object '{obj}' names {len(objects)} objects", "give exactly one object name")
    write_scene_xml(load_spec(resolve_spec(hand)), objects[0], EnvConfig(), asset_root, out)
    console.print(f"[green]wrote[/] {out} [dim](view it: python -m mujoco.viewer --mjcf {out})[/]")
    return 0


def evaluate(policy: str, hands: list[str], objects: str, trials: int, seed: int, zero_shot: bool,
             json_out: Path | None, csv_out: Path | None, asset_root: str | None, console: Console) -> int:
    from dgz_cli.sim.config import EnvConfig
    from dgz_cli.sim.evaluate import run_episodes, summarize
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import atomic_write, load_spec

    if policy != "scripted":
        raise DgzError(f"--policy '{policy}': this dgz evaluates only the scripted baseline",
                       "use --policy scripted (trained MAGCN checkpoints are not part of this release)")
    if zero_shot:
        raise DgzError("--zero-shot needs a trained policy's list of training hands", "drop --zero-shot for --policy scripted")
    cfg = EnvConfig()
    specs = [load_spec(resolve_spec(h)) for h in hands]
    objs = resolve_objects(objects, asset_root)
    pairs = [(s, o) for s in specs for o in objs]
    t0 = time.perf_counter()
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=True) as bar:
        task = bar.add_task(f"{policy}: {len(specs)} hand(s) × {len(objs)} object(s) × {trials} trials",
                            total=len(pairs) * trials)
        from dgz_cli.sim.scripted import ScriptedGrasp

        records: list[dict] = []
        for spec in specs:  # one env per hand keeps memory flat (one scene per object, not per pair)
            before = len(records)
            records += run_episodes([(spec, o) for o in objs], lambda env: ScriptedGrasp(env.N, env.grasp_offset),
                                    trials, cfg, seed, asset_root,
                                    progress=lambda done, total: bar.update(task, completed=before + done))
    summary = summarize(records)
    protocol = dict(lift_height_m=cfg.lift_height, hold_s=cfg.hold_s, success_fraction=cfg.success_fraction,
                    trials_per_object=trials, seed=seed, episode_steps=cfg.episode_steps)
    table = Table(title=f"{policy} — success = object lifted {cfg.lift_height} m (≥ {cfg.success_fraction:.0%} kept) "
                        f"and held {cfg.hold_s} s; {trials} trials per object, seed {seed}")
    table.add_column("hand")
    table.add_column("success rate", justify="right")
    table.add_column("episodes", justify="right")
    for name, h in summary.items():
        table.add_row(name, f"{h['success_rate']:.3f}", str(h["episodes"]))
    console.print(table)
    console.print(f"[dim]{len(records)} episodes in {time.perf_counter() - t0:.0f} s[/]")
    if json_out is not None:
        report = dict(policy=policy, protocol=protocol,
                      hands={k: dict(success_rate=v["success_rate"], episodes=v["episodes"], objects=v["objects"])
                             for k, v in summary.items()})
        atomic_write(json_out, json.dumps(report, indent=2) + "\n")
    if csv_out is not None:
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(["hand", "object", "trial", "success", "max_rise_m", "return"])
        for r in records:
            w.writerow([r["hand"], r["object"], r["trial"], int(r["success"]), f"{r['max_rise']:.4f}", f"{r['return_']:.3f}"])
        atomic_write(csv_out, buf.getvalue())
    return 0
