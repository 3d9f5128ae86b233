"""`dgz bench onboard`: wall time of each onboarding stage per shipped hand (median of N runs); with
``--process``, the wall time of a whole `dgz onboard` process as a user sees it from the shell; with
``--generated N``, onboarding's agreement and refusal rates over N generated hands."""

from __future__ import annotations

import os
import platform
import resource
import statistics
import tempfile
import time
from pathlib import Path


def _one(urdf: Path, name: str, xacro_args: dict, tmp: Path) -> dict[str, float]:
    from dgz_cli.onboard import excite, frame, structure
    from dgz_cli.onboard.compile import Poser, compile_model
    from dgz_cli.onboard.pipeline import onboard
    from dgz_cli.onboard.urdf import load_kinematics
    from dgz_cli.spec.io import write_spec

    t0 = time.perf_counter()
    kin = load_kinematics(urdf, xacro_args)
    t1 = time.perf_counter()
    poser = Poser(kin, compile_model(kin))
    t2 = time.perf_counter()
    st = structure.analyse(kin, poser)
    fr = frame.estimate(kin, poser, st)
    excite.Exciter(kin, poser, st, fr, excite.ExcitationSettings()).run()
    t3 = time.perf_counter()
    spec = onboard(urdf, name, None, None, xacro_args).spec  # full pipeline incl. nodes/features
    t4 = time.perf_counter()
    write_spec(spec, tmp / f"{name}.yaml")
    t5 = time.perf_counter()
    return dict(parse_s=t1 - t0, compile_s=t2 - t1, excite_s=t3 - t2, pipeline_s=t4 - t3, write_s=t5 - t4)


def run(hands: list[str] | None, repeat: int, asset_root: str | None) -> dict:
    from dgz_cli.spec.catalog import resolve_spec, resolve_urdf, shipped_hands
    from dgz_cli.spec.io import load_spec

    names = hands or shipped_hands()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            spec = load_spec(resolve_spec(name))
            urdf = resolve_urdf(spec.provenance.urdf, asset_root)
            runs = [_one(urdf, name, dict(spec.provenance.xacro_args), Path(tmp)) for _ in range(repeat)]
            med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
            med["onboard_s"] = med["pipeline_s"] + med["write_s"]  # `dgz onboard` end to end (parse..write)
            rows[name] = {k: round(v, 4) for k, v in med.items()}
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    total = sum(r["onboard_s"] for r in rows.values())
    return dict(benchmark="onboard", repeat=repeat, machine=platform.processor() or platform.machine(),
                python=platform.python_version(), hands=rows,
                throughput_hands_per_s=round(len(rows) / total, 3) if total else None,
                latency_max_s=max((r["onboard_s"] for r in rows.values()), default=None),
                peak_rss_mb=round(peak_mb, 1))


def generated(count: int, seed: int, variants_of: str | None = None, asset_root: str | None = None) -> dict:
    """Agreement with the ground truth over ``count`` generated hands (or variants of one hand), as
    `dgz hands check` computes it (:mod:`dgz_cli.onboard.agreement`)."""
    from dgz_cli.onboard.agreement import check_dir, summary
    from dgz_cli.onboard.generate import KINDS, write_hands

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="dgz-bench-generated-") as tmp:
        if variants_of is None:
            write_hands(Path(tmp), seed, count)
        else:
            from dgz_cli.onboard.variants import write_variants
            from dgz_cli.spec.catalog import asset_root as resolve_root
            from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
            from dgz_cli.spec.io import load_spec

            spec = load_spec(resolve_spec(variants_of))
            write_variants(spec, resolve_urdf(spec.provenance.urdf, resolve_root(asset_root)), Path(tmp), seed, count)
        result = summary(check_dir(Path(tmp)))
    return dict(benchmark="onboard-generated", seed=seed, kinds=list(KINDS) if variants_of is None else None,
                variants_of=variants_of, **result, total_s=round(time.perf_counter() - t0, 2),
                load_average=[round(x, 2) for x in os.getloadavg()],
                machine=platform.processor() or platform.machine(), python=platform.python_version())


def _import_seconds(stderr: str) -> float:
    """Sum of the top-level cumulative times that ``python -X importtime`` printed (the process's imports)."""
    total = 0
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, cumulative, name = line.split("|", 2)
        if name.startswith(" ") and not name.startswith("  ") and cumulative.strip().isdigit():
            total += int(cumulative)
    return total / 1e6


def _child_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def process(hands: list[str] | None, repeat: int, asset_root: str | None) -> dict:
    """Each shipped hand onboarded by a fresh `dgz onboard URDF -o TMP` process (``python -m dgz_cli.cli.app``,
    what the console script runs): wall time from spawn to exit (median of ``repeat``), the process's CPU
    time, and, from one more run under ``-X importtime``, the time its imports took inside the process."""
    import subprocess
    import sys

    from dgz_cli.spec.catalog import asset_root as resolve_root
    from dgz_cli.spec.catalog import hand_dir, resolve_spec, resolve_urdf, shipped_hands
    from dgz_cli.spec.io import load_spec

    names = hands or shipped_hands()
    root = resolve_root(asset_root)
    env = dict(os.environ, **({"DGZ_ASSET_ROOT": str(root)} if root else {}))
    cmd0 = [sys.executable, "-m", "dgz_cli.cli.app", "onboard"]
    load_before = os.getloadavg()

    def spawn(argv: list[str]) -> tuple[float, float, subprocess.CompletedProcess]:
        c0, t0 = _child_cpu(), time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True, env=env)
        return time.perf_counter() - t0, _child_cpu() - c0, done

    rows = {}
    t_start = time.perf_counter()
    baseline = statistics.median(spawn([sys.executable, "-c", "pass"])[0] for _ in range(repeat))
    with tempfile.TemporaryDirectory(prefix="dgz-bench-onboard-") as tmp:
        for name in names:
            spec = load_spec(resolve_spec(name))
            urdf = resolve_urdf(spec.provenance.urdf, asset_root)
            args = [str(urdf), "-o", str(Path(tmp) / f"{name}.yaml"), "--name", name]
            args += [f"--xacro-arg={k}={v}" for k, v in spec.provenance.xacro_args.items()]
            overrides = hand_dir(name) / "overrides.yaml"
            if overrides.is_file():
                args += ["--overrides", str(overrides)]
            runs = [spawn(cmd0 + args) for _ in range(repeat)]
            if any(r[2].returncode != 0 for r in runs):
                bad = next(r[2] for r in runs if r[2].returncode != 0)
                raise RuntimeError(f"dgz onboard {name} failed: {bad.stderr.strip()[-300:]}")
            *_, traced = spawn([sys.executable, "-X", "importtime"] + cmd0[1:] + args)
            rows[name] = dict(wall_s=round(statistics.median(r[0] for r in runs), 3),
                              cpu_s=round(statistics.median(r[1] for r in runs), 3),
                              import_s=round(_import_seconds(traced.stderr), 3))
    walls = [r["wall_s"] for r in rows.values()]
    return dict(benchmark="onboard-process", repeat=repeat, command=" ".join(cmd0[1:]) + " URDF -o TMP",
                hands=rows, wall_max_s=max(walls, default=None), target_s=0.5,
                target_met=bool(walls) and max(walls) <= 0.5, python_startup_s=round(baseline, 3),
                load_average_before=[round(x, 2) for x in load_before],
                load_average_after=[round(x, 2) for x in os.getloadavg()],
                total_s=round(time.perf_counter() - t_start, 1), cpus=os.cpu_count(),
                machine=platform.processor() or platform.machine(), python=platform.python_version())
