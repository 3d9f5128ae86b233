"""`dgz bench sim`: env control steps/s vs raw ``mj_step`` control steps/s on the same scenes.

Raw = the same slots, from the same start states, stepped by the same worker threads with the
same control sequence the env produced (recorded, then replayed with ``mj_step(nstep=substeps)``)
but no action mapping, observation or reward — so both do identical physics. Repeated 3 times;
medians reported. ``steps`` must stay below an episode (190 steps) so no slot resets mid-run.
"""

from __future__ import annotations

import platform
import resource
import statistics
import time


def run(hands: list[str], objects: str, envs: int, steps: int, threads: int, asset_root: str | None) -> dict:
    import mujoco
    import numpy as np

    from dgz_cli.sim.config import EnvConfig
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    objs = resolve_objects(objects, asset_root)
    specs = [load_spec(resolve_spec(h)) for h in hands]
    pairs = [(specs[i % len(specs)], objs[(i // len(specs)) % len(objs)]) for i in range(envs)]
    t0 = time.perf_counter()
    env = GraspEnv(pairs, EnvConfig(), seed=0, asset_root=asset_root, threads=threads)
    build_s = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    substeps = env.cfg.substeps

    def raw_step(chunk: list[int]) -> None:
        for b in chunk:
            s = env.slots[b]
            mujoco.mj_step(s.model, s.data, nstep=substeps)

    spec_state = mujoco.mjtState.mjSTATE_INTEGRATION
    steps = min(steps, env.cfg.episode_steps - 1)
    actions = [rng.uniform(-1, 1, (env.B, env.action_dim)) for _ in range(steps)]
    env_rates, raw_rates, latencies = [], [], []
    for _ in range(3):
        env.reset(0)
        start = []
        for s in env.slots:
            state = np.zeros(mujoco.mj_stateSize(s.model, spec_state))
            mujoco.mj_getState(s.model, s.data, state, spec_state)
            start.append(state)
        ctrls = []
        t = time.perf_counter()
        for a in actions:
            t1 = time.perf_counter()
            env.step(a)
            latencies.append(time.perf_counter() - t1)
            ctrls.append([s.data.ctrl.copy() for s in env.slots])
        env_rates.append(steps * env.B / (time.perf_counter() - t))
        for s, state in zip(env.slots, start):
            mujoco.mj_setState(s.model, s.data, state, spec_state)

        def raw_step(chunk: list[int], k: int) -> None:
            for b in chunk:
                s = env.slots[b]
                s.data.ctrl[:] = ctrls[k][b]
                mujoco.mj_step(s.model, s.data, nstep=substeps)

        t = time.perf_counter()
        for k in range(steps):
            if env.pool is None:
                raw_step(list(range(env.B)), k)
            else:
                list(env.pool.map(raw_step, env.chunks, [k] * len(env.chunks)))
        raw_rates.append(steps * env.B / (time.perf_counter() - t))
    env.close()
    env_rate, raw_rate = statistics.median(env_rates), statistics.median(raw_rates)
    return dict(
        benchmark="sim", hands=hands, objects=objects, envs=env.B, threads=threads, substeps=substeps,
        build_s=round(build_s, 3),
        env_control_steps_per_s=round(env_rate, 1), raw_control_steps_per_s=round(raw_rate, 1),
        ratio=round(env_rate / raw_rate, 3), env_step_latency_ms=round(1000 * statistics.median(latencies), 2),
        physics_substeps_per_s=round(raw_rate * substeps, 0), instabilities=env.instabilities,
        peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        machine=platform.machine(), python=platform.python_version(),
    )
