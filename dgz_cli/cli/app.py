"""The `dgz` command line. Only this layer imports typer/rich; heavy modules load inside commands."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console

from dgz_cli import __version__
from dgz_cli.spec.errors import DgzError

try:  # typer ≥ 0.2x vendors click; older typer uses click directly
    from typer import TyperException as _UsageError
except ImportError:  # pragma: no cover
    from click import ClickException as _UsageError

app = typer.Typer(no_args_is_help=True, pretty_exceptions_enable=False, add_completion=False,
                  help="dgz — DexGrasp-Zero: onboard any dexterous hand from its URDF and grasp with one policy.")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks that print JSON (throughput, latency, peak memory).")
app.add_typer(bench_app, name="bench")
from dgz_cli.cli.hands_cmd import hands_app  # noqa: E402  (typer sub-app; heavy modules load inside its commands)

app.add_typer(hands_app, name="hands")
assets_app = typer.Typer(no_args_is_help=True, help="Hand and object models from their pinned upstream repositories.")
app.add_typer(assets_app, name="assets")
out = Console(emoji=False)  # names from input files: no :emoji: codes (markup is escaped where printed)
err = Console(stderr=True, emoji=False)

ASSET_HELP = "folder holding hands/ and objects/ (default: $DGZ_ASSET_ROOT)"


def _version(value: bool) -> None:
    if value:
        out.print(f"dgz {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print the version and exit")) -> None:
    pass


def _parse_kv(items: list[str] | None) -> dict[str, str]:
    result = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise DgzError(f"--xacro-arg '{item}' is not KEY=VALUE", "write e.g. --xacro-arg side:=right as side=right")
        result[key] = value
    return result


@app.command()
def onboard(
    urdf: Path = typer.Argument(..., help="hand URDF or .xacro file"),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="spec to write (default: ./NAME.yaml)"),
    name: Optional[str] = typer.Option(None, "--name", help="hand name (default: from the file name)"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    palm_link: Optional[str] = typer.Option(None, "--palm-link", help="palm link, when auto-detection cannot decide"),
    xacro_arg: Optional[List[str]] = typer.Option(None, "--xacro-arg", help="KEY=VALUE passed to xacro (repeatable)"),
    overrides_file: Optional[Path] = typer.Option(None, "--overrides", help="YAML of human overrides (see docs)"),
    as_json: bool = typer.Option(False, "--json", help="print a machine-readable summary on stdout"),
) -> None:
    """Read a URDF/xacro, identify nodes and M_h by unit-joint excitation, lint and write a HandSpec."""
    from dgz_cli.cli import onboard_cmd

    code = onboard_cmd.run(urdf, out_path, name, asset_root, palm_link, _parse_kv(xacro_arg), overrides_file,
                           as_json, out)
    raise typer.Exit(code)


@app.command()
def lint(
    specs: List[str] = typer.Argument(..., help="spec files or shipped hand names"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    as_json: bool = typer.Option(False, "--json", help="print findings as JSON"),
) -> None:
    """Check HandSpecs: schema, node tree, M_h, mask, features, and agreement with their URDF."""
    from dgz_cli.cli import lint_cmd

    raise typer.Exit(lint_cmd.run(specs, asset_root, as_json, out))


@app.command()
def show(
    spec: Optional[str] = typer.Argument(None, help="spec file or shipped hand name"),
    png: Optional[Path] = typer.Option(None, "--png", help="also draw the graph over the skeleton into this PNG"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    list_hands: bool = typer.Option(False, "--list", help="list the shipped hands"),
) -> None:
    """Print a hand's semantic nodes, M_h and mask; optionally draw them (--png)."""
    from dgz_cli.cli import show_cmd

    raise typer.Exit(show_cmd.run(spec, png, asset_root, list_hands, out))


@app.command()
def schema(overrides: bool = typer.Option(False, "--overrides", help="print the overrides file schema instead")) -> None:
    """Print the HandSpec JSON schema (for editor validation of spec YAML)."""
    from dgz_cli.spec.models import HandSpec, Overrides

    model = Overrides if overrides else HandSpec
    sys.stdout.write(json.dumps(model.model_json_schema(), indent=2) + "\n")


def _train_default(field: str) -> str:
    """A TrainConfig field's description and default, for --help (the config model is the one source)."""
    from dgz_cli.rl.config import TrainConfig

    f = TrainConfig.model_fields[field]
    default = ",".join(f.default) if isinstance(f.default, tuple) else f.default
    return f"{f.description or field} (default: {default})"


@app.command()
def train(
    out_dir: Path = typer.Option(..., "--out", help="run directory (checkpoints, logs, curve)"),
    config: Optional[Path] = typer.Option(None, "--config", help="YAML run config (any TrainConfig field, including "
                                          "ppo: {...} hyper-parameters); options given here override it"),
    hands: Optional[str] = typer.Option(None, "--hands", help="comma-separated " + _train_default("hands")),
    objects: Optional[str] = typer.Option(None, "--objects", help=_train_default("objects")),
    preset: Optional[str] = typer.Option(None, "--preset", help=_train_default("preset")),
    ablation: Optional[str] = typer.Option(None, "--ablation", help=_train_default("ablation")),
    iterations: Optional[int] = typer.Option(None, "--iterations", help=_train_default("iterations")),
    repeat: Optional[int] = typer.Option(None, "--repeat", help=_train_default("repeat")),
    steps: Optional[int] = typer.Option(None, "--steps", help=_train_default("steps_per_env")),
    checkpoint_every: Optional[int] = typer.Option(None, "--checkpoint-every", help=_train_default("checkpoint_every")),
    seed: Optional[int] = typer.Option(None, "--seed", help=_train_default("seed")),
    bc_episodes: Optional[int] = typer.Option(None, "--bc-episodes", help=_train_default("bc_episodes")),
    bc_epochs: Optional[int] = typer.Option(None, "--bc-epochs", help=_train_default("bc_epochs")),
    bc_dagger: Optional[int] = typer.Option(None, "--bc-dagger", help=_train_default("bc_dagger_rounds")),
    lift_weight: Optional[float] = typer.Option(None, "--lift-weight", help=_train_default("lift_weight")),
    init_from: Optional[str] = typer.Option(None, "--init-from", help=_train_default("init_from")),
    resume: bool = typer.Option(False, "--resume", help="continue the run in --out from its last checkpoint "
                                "(its recorded config; --iterations may extend it)"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
) -> None:
    """Train one MAGCN policy on several hands with PPO (paper hyper-parameters)."""
    from dgz_cli.cli import train_cmd

    given = dict(hands=None if hands is None else tuple(h for h in hands.split(",") if h), objects=objects,
                 preset=preset, ablation=ablation, iterations=iterations, repeat=repeat, steps_per_env=steps,
                 checkpoint_every=checkpoint_every, seed=seed, bc_episodes=bc_episodes, bc_epochs=bc_epochs,
                 bc_dagger_rounds=bc_dagger, lift_weight=lift_weight, init_from=init_from)
    raise typer.Exit(train_cmd.run({k: v for k, v in given.items() if v is not None}, config, out_dir, resume,
                                   asset_root, out))


def _distill_default(field: str) -> str:
    """A DistillConfig field's description and default, for --help (the config model is the one source)."""
    from dgz_cli.rl.distill_config import DistillConfig

    f = DistillConfig.model_fields[field]
    default = ",".join(f.default) if isinstance(f.default, tuple) else f.default
    return f"{f.description or field} (default: {default})"


@app.command()
def distill(
    out_dir: Path = typer.Option(..., "--out", help="run directory (checkpoints, logs, curve)"),
    teacher: Optional[str] = typer.Option(None, "--teacher", help="the privileged teacher: a `dgz train` checkpoint "
                                          "folder or a name under policies/ (e.g. dgz-cpu-warmstart)"),
    hands: Optional[str] = typer.Option(None, "--hands", help="comma-separated " + _distill_default("hands")),
    objects: Optional[str] = typer.Option(None, "--objects", help=_distill_default("objects")),
    repeat: Optional[int] = typer.Option(None, "--repeat", help=_distill_default("repeat")),
    iterations: Optional[int] = typer.Option(None, "--iterations", help=_distill_default("iterations")),
    steps: Optional[int] = typer.Option(None, "--steps", help=_distill_default("steps_per_env")),
    epochs: Optional[int] = typer.Option(None, "--epochs", help=_distill_default("epochs")),
    learning_rate: Optional[float] = typer.Option(None, "--learning-rate", help=_distill_default("learning_rate")),
    finetune_iterations: Optional[int] = typer.Option(None, "--finetune-iterations",
                                                      help=_distill_default("finetune_iterations")),
    joint_noise: Optional[float] = typer.Option(None, "--joint-noise", help="rad: std of the noise on the student's "
                                                "joint readings (default: 0.01)"),
    held_cloud: Optional[bool] = typer.Option(None, "--held-cloud/--live-cloud", help="the student sees the object "
                                              "cloud of the first frame, held, its centroid the target (default), or "
                                              "the simulator's live cloud"),
    settle: Optional[float] = typer.Option(None, "--settle", help="s the object settles on the table before each "
                                           "episode's first frame (default: the teacher's env, 0.3 s unless it was "
                                           "trained with settle_s)"),
    teacher_view: Optional[str] = typer.Option(None, "--teacher-view", help="what the teacher labels from: sim (the "
                                               "simulator's observation, default) or student (the student's view "
                                               "plus contact and force, for a teacher trained with train_view)"),
    history: Optional[int] = typer.Option(None, "--history", help="steps the student's LSTM sees, the current one "
                                          "included (default: 5, the paper's)"),
    checkpoint_every: Optional[int] = typer.Option(None, "--checkpoint-every", help=_distill_default("checkpoint_every")),
    seed: Optional[int] = typer.Option(None, "--seed", help=_distill_default("seed")),
    resume: bool = typer.Option(False, "--resume", help="continue the run in --out from its last checkpoint "
                                "(its recorded config; --iterations/--finetune-iterations may extend it)"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
) -> None:
    """Distil a privileged teacher into a student that needs no contact or force input (DAgger, then optional PPO)."""
    from dgz_cli.cli import distill_cmd

    given = dict(teacher=teacher, hands=None if hands is None else tuple(h for h in hands.split(",") if h),
                 objects=objects, repeat=repeat, iterations=iterations, steps=steps, epochs=epochs,
                 learning_rate=learning_rate, finetune_iterations=finetune_iterations, joint_noise=joint_noise,
                 held_cloud=held_cloud, history=history, checkpoint_every=checkpoint_every, seed=seed,
                 settle=settle, teacher_view=teacher_view)
    raise typer.Exit(distill_cmd.run({k: v for k, v in given.items() if v is not None}, out_dir, resume, asset_root,
                                     out))


@app.command()
def scene(
    hand: str = typer.Option(..., "--hand", help="shipped hand name or spec file"),
    obj: str = typer.Option(..., "--object", help="object: a YCB-45 folder name (025_mug) or sphere/box/cylinder/capsule"),
    out_path: Path = typer.Option(..., "-o", "--out", help="MJCF file to write"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
) -> None:
    """Write a standalone MuJoCo scene (hand on a 6-DoF wrist + object + table) for MuJoCo's viewer."""
    from dgz_cli.cli import sim_cmd

    raise typer.Exit(sim_cmd.scene(hand, obj, out_path, asset_root, out))


@app.command("eval")
def evaluate(
    policy: str = typer.Option("scripted", "--policy", help="'scripted' (the spec-only baseline), a run/policy "
                               "directory, or a name under policies/"),
    hand: Optional[List[str]] = typer.Option(None, "--hand", help="shipped hand name, spec file, or generated:DIR "
                                             "(every hand `dgz hands generate` wrote into DIR, onboarded there as "
                                             "for `dgz train`); comma-separated or repeated"),
    objects: str = typer.Option("ycb45", "--objects", help="ycb45, primitives, or comma-separated object names"),
    trials: int = typer.Option(25, "--trials", min=1, help="episodes per (hand, object)"),
    seed: int = typer.Option(0, "--seed", help="randomization seed"),
    zero_shot: bool = typer.Option(False, "--zero-shot", help="refuse hands the policy was trained on"),
    json_out: Optional[Path] = typer.Option(None, "--json", help="write results as JSON"),
    csv_out: Optional[Path] = typer.Option(None, "--csv", help="write per-episode rows as CSV"),
    table: Optional[List[Path]] = typer.Option(None, "--table", help="print Table I from `--json` result files "
                                               "(repeatable) instead of evaluating; a --policy scripted file is the "
                                               "scripted baseline row"),
    paper: Optional[bool] = typer.Option(None, "--paper/--no-paper", help="with --table: also print the paper's "
                                         "Table I rows, quoted (default: when a file has one of its hands)"),
    by_object: bool = typer.Option(False, "--by-object", help="with --table: success per object instead (rows: "
                                   "objects, hardest first; one file: a column per hand, several: each file's "
                                   "mean over its hands)"),
    guidance: float = typer.Option(0.0, "--guidance", help="with --policy scripted: the contract's wrist guidance "
                                   "gain (a checkpoint always runs under its own contract)"),
    guidance_stop_gap: Optional[float] = typer.Option(None, "--guidance-stop-gap", help="with --policy scripted "
                                                      "and --guidance: the guidance stops moving the palm toward the "
                                                      "object along its normal once the palm is this many m from its "
                                                      "surface (default: it presses on; a checkpoint uses its own)"),
    roll: Optional[str] = typer.Option(None, "--roll", help="start roll: uniform, narrow (closing across the "
                                       "object's narrowest width) or clear (narrow among the rolls whose hand clears "
                                       "the table) (default: the checkpoint's own; uniform for scripted)"),
    physics_hz: Optional[float] = typer.Option(None, "--physics-hz", help="with --policy scripted: physics rate, a "
                                               "whole multiple of the 20 Hz control rate (default: the contract's "
                                               "400; a checkpoint uses its own)"),
    thumb_open: Optional[float] = typer.Option(None, "--thumb-open", help="with --policy scripted: start pose with "
                                               "the thumb's ABD joints this fraction (0 to 1) of the way to their "
                                               "+ABD limit; 1 = the paper's pre-grasp (default: 0, the flat open "
                                               "hand; a checkpoint uses its own)"),
    video: Optional[Path] = typer.Option(None, "--video", help="also render episodes offscreen into this folder: "
                                         "MP4 per episode + contact_sheet.png (needs EGL or OSMesa; skipped with a "
                                         "message where there is none)"),
    video_episodes: int = typer.Option(2, "--video-episodes", min=1, max=20, help="with --video: episodes per hand, "
                                       "on the first object"),
    perturb: bool = typer.Option(True, "--perturb/--no-perturb", help="a distilled student observes under the "
                                 "hardware perturbations recorded in its checkpoint (default), or the simulator's "
                                 "observation; no effect on other policies"),
    feature_scale: float = typer.Option(1.0, "--feature-scale", help="URDF-prior sensitivity: scale every link "
                                        "length of the evaluated hands by this (> 0) in the policy's physical "
                                        "features only; the simulated hand and the protocol are unchanged"),
    approach_cone: Optional[float] = typer.Option(None, "--approach-cone", help="start state: max tilt (rad, "
                                                  "0 to π/2) of the approach direction from vertical; 0 = straight "
                                                  "above the object, the paper's Barrett protocol (default: the "
                                                  "checkpoint's own; 0.5 for scripted)"),
    settle: Optional[float] = typer.Option(None, "--settle", help="start state: seconds (0 to 10) the dropped "
                                           "object settles on the table before the episode's first frame "
                                           "(default: the checkpoint's own; 0.3 for scripted)"),
    object_orientation: Optional[str] = typer.Option(None, "--object-orientation", help="start state: random (the "
                                                     "object dropped in any orientation) or upright (in its model's "
                                                     "frame, z up, with a random yaw; GraspXL's and RobustDexGrasp's "
                                                     "placement) (default: the checkpoint's own; random for scripted)"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
) -> None:
    """Success rate per hand and object under the protocol (lift, hold), with both cores; the closing onset
    (step and palm → object distance where the fingers start to close) per hand and episode."""
    from dgz_cli.cli import sim_cmd

    if table:
        from dgz_cli.cli.eval_table import render_object_table, render_table

        raise typer.Exit(render_object_table(table, out) if by_object else render_table(table, out, paper))
    if by_object:
        raise DgzError("--by-object without --table", "give result files: --table a.json --by-object")
    if not hand:
        raise DgzError("no --hand given", "name one or more hands, e.g. --hand leap --hand inspire")
    import math

    if not (math.isfinite(feature_scale) and feature_scale > 0):
        raise DgzError(f"--feature-scale {feature_scale}: must be a finite number > 0", "e.g. --feature-scale 2")
    if approach_cone is not None and not 0.0 <= approach_cone <= math.pi / 2:
        raise DgzError(f"--approach-cone {approach_cone}: must be in [0, π/2] rad",
                       "0 approaches from straight above; the default cone is 0.5")
    from dgz_cli.spec.envconfig import MAX_SETTLE_S

    if settle is not None and not (math.isfinite(settle) and 0.0 <= settle <= MAX_SETTLE_S):
        raise DgzError(f"--settle {settle}: must be in [0, {MAX_SETTLE_S:g}] s", "e.g. --settle 2 (the default is 0.3)")
    if object_orientation is not None and object_orientation not in ("random", "upright"):
        raise DgzError(f"--object-orientation {object_orientation!r} is not supported",
                       "use --object-orientation random or upright")
    hands = [h for item in hand for h in item.split(",") if h]
    raise typer.Exit(sim_cmd.evaluate(policy, hands, objects, trials, seed, zero_shot, json_out, csv_out,
                                      asset_root, out, guidance=guidance, guidance_stop_gap=guidance_stop_gap,
                                      roll=roll, video=video,
                                      video_episodes=video_episodes, perturb=perturb, feature_scale=feature_scale,
                                      approach_cone=approach_cone, physics_hz=physics_hz, thumb_open=thumb_open,
                                      settle=settle, object_orientation=object_orientation))


@assets_app.command("fetch")
def assets_fetch(
    hands: Optional[List[str]] = typer.Option(None, "--hands", help="hands to fetch, comma-separated or repeated "
                                              "(default: all; 'none' for no hand)"),
    objects: Optional[List[str]] = typer.Option(None, "--objects", help="object sets: ycb45 (default) or none"),
    dest: Optional[Path] = typer.Option(None, "--dest", help="asset root to fill (default: the user's cache folder, "
                                        "where dgz finds it without DGZ_ASSET_ROOT)"),
    mirror: Optional[str] = typer.Option(None, "--mirror", help="base URL serving the pinned archives by file name "
                                         "(default: $DGZ_ASSET_MIRROR, else the upstream hosts)"),
    force: bool = typer.Option(False, "--force", help="fetch again even where the files verify"),
    registry: Optional[Path] = typer.Option(None, "--registry", help="another asset registry (JSON, same schema as "
                                            "dgz_cli/assets/registry.json)"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress bars"),
) -> None:
    """Download the pinned upstream archives, verify every file's sha256 and lay out hands/ and objects/ycb45/."""
    from dgz_cli.cli import assets_cmd

    raise typer.Exit(assets_cmd.fetch(hands, objects, dest, mirror, force, registry, out, progress=not quiet))


@bench_app.command("train")
def bench_train(
    config: Optional[Path] = typer.Option(None, "--config", help="YAML run config, as for `dgz train --config`"),
    hands: str = typer.Option("allegro,shadow,schunk_svh,ability", "--hands", help="comma-separated training hands"),
    objects: str = typer.Option("004_sugar_box,013_apple,025_mug,061_foam_brick", "--objects",
                                help="ycb45, primitives, or comma-separated object names"),
    repeat: int = typer.Option(3, "--repeat", min=1, help="N_env = hands × objects × repeat"),
    steps: int = typer.Option(130, "--steps", min=1, help="transitions per env per iteration"),
    iterations: int = typer.Option(2, "--iterations", min=1, help="PPO iterations measured"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    as_json: bool = typer.Option(False, "--json", help="print only the JSON"),
) -> None:
    """End-to-end training transitions/s, its split (physics, env, forward, update), peak RSS, MuJoCo profile."""
    from dgz_cli.cli import train_cmd

    given = dict(hands=tuple(h for h in hands.split(",") if h), objects=objects, repeat=repeat, steps_per_env=steps)
    result = train_cmd.bench(given, config, iterations, asset_root)
    if not as_json:
        f = result["split_fraction"]
        out.print(f"{result['transitions_per_s']} transitions/s (physics {f['physics_s']:.0%}, env {f['env_other_s']:.0%}, "
                  f"forward {f['policy_forward_s']:.0%}, update {f['ppo_update_s']:.0%}), peak RSS {result['peak_rss_mb']} MB")
    sys.stdout.write(json.dumps(result, indent=2) + "\n")


@bench_app.command("sim")
def bench_sim(
    hands: str = typer.Option("allegro,leap,inspire,ability", "--hands", help="comma-separated shipped hands"),
    objects: str = typer.Option("primitives", "--objects", help="objects to cycle through"),
    envs: int = typer.Option(32, "--envs", min=1, help="number of slots"),
    steps: int = typer.Option(150, "--steps", min=10, help="control steps per measurement (< one episode)"),
    threads: int = typer.Option(2, "--threads", min=1, help="physics worker threads"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    as_json: bool = typer.Option(False, "--json", help="print only the JSON"),
) -> None:
    """Env control steps/s vs raw mj_step control steps/s on the same scenes and control sequence."""
    from dgz_cli.bench import sim_bench

    result = sim_bench.run([h for h in hands.split(",") if h], objects, envs, steps, threads, asset_root)
    if not as_json:
        out.print(f"env {result['env_control_steps_per_s']} steps/s, raw {result['raw_control_steps_per_s']} "
                  f"steps/s, ratio {result['ratio']}")
    sys.stdout.write(json.dumps(result, indent=2) + "\n")


@app.command()
def deploy(
    hand: Optional[str] = typer.Option(None, "--hand", help="revo2, inspire, leap (hand files), a hand file path, or "
                                       "sim (the evaluation scene in MuJoCo, see --sim-hand/--sim-object/--seed)"),
    port: Optional[str] = typer.Option(None, "--port", help="serial port (prefer /dev/serial/by-id/...), or sim "
                                       "(this hand's spec in the MuJoCo evaluation scene)"),
    policy: str = typer.Option("dgz-cpu-student", "--policy",
                               help="the shipped student dgz-cpu-student (default: distilled, no contact/force "
                                    "input; needs the object), 'scripted' (the spec-only scripted grasp of `dgz "
                                    "eval`; needs the object), 'close' (blind close, no object needed), a trained "
                                    "checkpoint folder or a name under policies/, or package.module:factory"),
    object_points: Optional[Path] = typer.Option(None, "--object-points",
                                                 help="object point cloud: .npy (P, 3) or 'x y z' lines, metres, "
                                                      "palm frame (f, l, n) at the start pose; or sphere, box, "
                                                      "cylinder, capsule: that built-in object 0.25 m in front of "
                                                      "the palm"),
    allow_privileged: bool = typer.Option(False, "--allow-privileged",
                                          help="run a policy that observes contact flags/forces (a teacher) with "
                                               "those inputs fed as zeros; for tests, not for grasping"),
    arm: str = typer.Option("none", "--arm", help="wrist command goes to: none (logged only), sim (ideal arm), "
                                                  "piper (AgileX Piper via piper-sdk), or an arm file path"),
    arm_port: Optional[str] = typer.Option(None, "--arm-port", help="CAN interface of the arm (default: from the arm file, can0)"),
    dry_run: bool = typer.Option(False, "--dry-run", help="connect and read only: never write to the hand"),
    fake: bool = typer.Option(False, "--fake", help="start the hand's fake device on a pseudo-terminal and connect to it"),
    yes: bool = typer.Option(False, "--yes", help="do not ask before the hand moves"),
    log: Optional[Path] = typer.Option(None, "--log", help="write every step as JSON lines to this file"),
    on_exit: str = typer.Option("hold", "--on-exit", help="hold or relax when the run ends or is stopped"),
    replay: Optional[Path] = typer.Option(None, "--replay", help="play a step log back on the simulated hand and exit"),
    sim_hand: Optional[str] = typer.Option(None, "--sim-hand", help="with --hand sim: the hand (shipped name or spec "
                                           "file; default dgz_tri, which needs no assets)"),
    sim_object: str = typer.Option("sphere", "--sim-object", help="with the MuJoCo backend: the object (a YCB-45 "
                                   "name or sphere/box/cylinder/capsule)"),
    seed: int = typer.Option(0, "--seed", help="with the MuJoCo backend: the reset seed (= trial 0 of `dgz eval "
                             "--seed` on that hand and object)"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
) -> None:
    """Run a grasp policy on a real hand (or its fake device, or the MuJoCo sim) with a safety filter."""
    from dgz_cli.cli import deploy_cmd

    raise typer.Exit(deploy_cmd.run(hand, port, policy, object_points, dry_run, fake, yes, log, on_exit, replay, out,
                                    asset_root=asset_root, allow_privileged=allow_privileged, arm=arm,
                                    arm_port=arm_port, sim_hand=sim_hand, sim_object=sim_object, seed=seed))


@bench_app.command("deploy")
def bench_deploy(
    hand: str = typer.Option("revo2", "--hand", help="revo2, inspire, leap (pty fake) or sim"),
    steps: int = typer.Option(200, "--steps", min=1, help="control steps at 20 Hz"),
) -> None:
    """Control-loop timing at 20 Hz against a hand's fake device or the sim: mean period, p99 jitter."""
    from dgz_cli.runtime import bench

    sys.stdout.write(json.dumps(bench.run(hand, steps), indent=2) + "\n")


@bench_app.command("policy")
def bench_policy(
    preset: str = typer.Option("compact", "--preset", help="compact or paper"),
    nodes: int = typer.Option(20, "--nodes", min=2, help="graph size for the synthetic graphs"),
    threads: int = typer.Option(1, "--threads", min=1, help="torch threads"),
    as_json: bool = typer.Option(False, "--json", help="print only the JSON"),
) -> None:
    """Batch-1 forward latency, forward graphs/s at batch 1024, PPO update samples/s, env+policy steps/s."""
    from dgz_cli.bench import policy_bench

    result = policy_bench.run(preset, nodes, threads)
    if not as_json:
        from rich.markup import escape

        out.print(f"{escape(preset)}: batch-1 forward {result['batch1_forward_ms']} ms, {result['forward_graphs_per_s_b1024']} "
                  f"graphs/s at 1024, PPO {result['ppo_update_samples_per_s']} samples/s")
    sys.stdout.write(json.dumps(result, indent=2) + "\n")


@bench_app.command("onboard")
def bench_onboard(
    hands: Optional[str] = typer.Option(None, "--hands", help="comma-separated shipped hands (default: all)"),
    repeat: int = typer.Option(3, "--repeat", min=1, help="runs per hand; the median is reported"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help=ASSET_HELP),
    as_json: bool = typer.Option(False, "--json", help="print only the JSON"),
    process: bool = typer.Option(False, "--process", help="time whole `dgz onboard URDF -o TMP` processes as from "
                                 "the shell: per hand wall time (median of --repeat), CPU time and import time"),
    generated: Optional[int] = typer.Option(None, "--generated", min=1, max=100000, help="instead: agreement and "
                                            "refusal rates of onboarding over N generated hands (as `dgz hands check`)"),
    seed: int = typer.Option(0, "--seed", help="with --generated: seed of the generated hands"),
    variants_of: Optional[str] = typer.Option(None, "--variants-of", help="with --generated: variants of this hand "
                                              "instead of random hands"),
) -> None:
    """Wall time per shipped hand for parse, compile, excite and write (one core); --process: whole processes;
    --generated N: agreement with the ground truth of generated hands."""
    from dgz_cli.bench import onboard_bench

    if generated is not None:
        result = onboard_bench.generated(generated, seed, variants_of, asset_root)
        if not as_json:
            out.print(f"{result['hands']} hands: agreement {result['agreement']:.1%}, refusal rate "
                      f"{result['refusal_rate']:.1%}, {result['wrong']} wrong but lint-clean, "
                      f"{result['false_refusal']} correct but refused, {result['truth_refused']} ground truths refused")
        sys.stdout.write(json.dumps(result, indent=2) + "\n")
        return
    if process:
        result = onboard_bench.process([h for h in (hands or "").split(",") if h] or None, repeat, asset_root)
        if not as_json:
            for name, r in result["hands"].items():
                out.print(f"{name}: {r['wall_s']:.2f} s wall, {r['cpu_s']:.2f} s CPU, imports {r['import_s']:.2f} s",
                          highlight=False, markup=False)
            out.print(f"slowest {result['wall_max_s']} s (target 0.5 s: {'met' if result['target_met'] else 'not met'}), "
                      f"load average {result['load_average_before']}", highlight=False, markup=False)
        sys.stdout.write(json.dumps(result, indent=2) + "\n")
        return
    result = onboard_bench.run([h for h in (hands or "").split(",") if h] or None, repeat, asset_root)
    if not as_json:
        from rich.markup import escape
        from rich.table import Table

        t = Table(title="dgz bench onboard (median seconds per hand)")
        cols = ["parse_s", "compile_s", "excite_s", "onboard_s"]
        t.add_column("hand")
        for c in cols:
            t.add_column(c, justify="right")
        for name, r in result["hands"].items():
            t.add_row(escape(str(name)), *(f"{r[c]:.3f}" for c in cols))
        out.print(t)
    sys.stdout.write(json.dumps(result, indent=2) + "\n")


def main() -> None:
    import os

    if sys.argv[1:2] == ["onboard"] and "MUJOCO_GL" not in os.environ:
        os.environ["MUJOCO_GL"] = "disable"  # a process that only onboards never renders: MuJoCo loads no GL library
    try:
        code = app(standalone_mode=False)  # in this mode typer returns the code of `raise typer.Exit(code)`
        if isinstance(code, int) and code != 0:
            sys.exit(code)
    except DgzError as exc:
        from rich.markup import escape

        err.print(f"[bold red]error:[/] {escape(exc.message)}" + (f" [dim]— {escape(exc.hint)}[/]" if exc.hint else ""),
                  soft_wrap=True, highlight=False, markup=True)
        sys.exit(1)
    except KeyboardInterrupt:
        err.print("[red]interrupted[/]")
        sys.exit(130)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except typer.Abort:
        sys.exit(1)
    except _UsageError as exc:  # bad options/arguments: typer prints usage and the problem
        exc.show()
        sys.exit(exc.exit_code)


if __name__ == "__main__":
    main()
