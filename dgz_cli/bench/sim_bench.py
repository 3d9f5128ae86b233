"""`dgz bench sim`: env control steps/s vs raw ``mj_step`` control steps/s on the same scenes.

Raw = the same slots, from the same start states, stepped by the same worker threads with the
same control sequence the env produced (recorded, then replayed with ``mj_step(nstep=substeps)``)
but no action mapping, observation or reward — so both do identical physics (``replay_identical``
checks that the replay ends in the env's state, bit for bit). The two alternate every ``BLOCK``
control steps (env block, restore the block's start state, raw replay of it), so a background load
that comes and goes hits both alike; only the ``env.step`` calls and the replay loop are timed.
Repeated 3 times; medians reported, per-repetition ratios in ``ratios``. ``steps`` must stay below
an episode (190 steps) so no slot resets mid-run.
"""

from __future__ import annotations

import platform
import resource
import statistics
import time

REPEATS = 3
BLOCK = 10  # control steps per env / raw alternation


def run(hands: list[str], objects: str, envs: int, steps: int, threads: int, asset_root: str | None) -> dict:
    import mujoco
    import numpy as np

    from dgz_cli.spec.envconfig import EnvConfig
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
    spec_state = mujoco.mjtState.mjSTATE_INTEGRATION  # includes the solver warm start: replays are exact

    def get_states() -> list[np.ndarray]:
        out = []
        for s in env.slots:
            state = np.zeros(mujoco.mj_stateSize(s.model, spec_state))
            mujoco.mj_getState(s.model, s.data, state, spec_state)
            out.append(state)
        return out

    def set_states(states: list[np.ndarray]) -> None:
        for s, state in zip(env.slots, states):
            mujoco.mj_setState(s.model, s.data, state, spec_state)

    def raw_step(chunk: list[int], ctrl: list[np.ndarray]) -> None:
        for b in chunk:
            s = env.slots[b]
            s.data.ctrl[:] = ctrl[b]
            mujoco.mj_step(s.model, s.data, nstep=substeps)

    steps = min(steps, env.cfg.episode_steps - 1)
    actions = [rng.uniform(-1, 1, (env.B, env.action_dim)) for _ in range(steps)]
    env_rates, raw_rates, latencies, identical = [], [], [], True
    for _ in range(REPEATS):
        env.reset(0)
        env_s = raw_s = 0.0
        for k0 in range(0, steps, BLOCK):  # env and raw alternate every BLOCK steps: both see the same load
            start = get_states()
            ctrls = []
            for a in actions[k0:k0 + BLOCK]:
                t = time.perf_counter()
                env.step(a)
                latencies.append(time.perf_counter() - t)
                ctrls.append([s.data.ctrl.copy() for s in env.slots])
            env_s += sum(latencies[-len(ctrls):])
            end = get_states()
            set_states(start)
            t = time.perf_counter()
            for ctrl in ctrls:
                if env.pool is None:
                    raw_step(list(range(env.B)), ctrl)
                else:
                    list(env.pool.map(raw_step, env.chunks, [ctrl] * len(env.chunks)))
            raw_s += time.perf_counter() - t
            identical &= all(np.array_equal(a, b) for a, b in zip(get_states(), end))
            set_states(end)  # the env goes on from its own state (the same, when the replay is exact)
        env_rates.append(steps * env.B / env_s)
        raw_rates.append(steps * env.B / raw_s)
    env.close()
    env_rate, raw_rate = statistics.median(env_rates), statistics.median(raw_rates)
    return dict(
        benchmark="sim", hands=hands, objects=objects, envs=env.B, threads=threads, substeps=substeps,
        build_s=round(build_s, 3),
        env_control_steps_per_s=round(env_rate, 1), raw_control_steps_per_s=round(raw_rate, 1),
        ratio=round(env_rate / raw_rate, 3), ratios=[round(e / r, 3) for e, r in zip(env_rates, raw_rates)],
        replay_identical=bool(identical), env_step_latency_ms=round(1000 * statistics.median(latencies), 2),
        physics_substeps_per_s=round(raw_rate * substeps, 0), instabilities=env.instabilities,
        peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        machine=platform.machine(), python=platform.python_version(),
    )
