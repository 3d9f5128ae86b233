"""`dgz bench onboard`: wall time of each onboarding stage per shipped hand (median of N runs)."""

from __future__ import annotations

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
