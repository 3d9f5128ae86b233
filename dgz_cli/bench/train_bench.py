"""`dgz bench train`: end-to-end PPO training throughput and where the time goes.

The CLI's composition root builds the Trainer (and its env) from a TrainConfig exactly as `dgz train` does;
this module runs ``iterations`` PPO iterations on it into a throw-away folder and reports transitions/s,
the wall-clock split (physics, rest of the env, policy forward, PPO update) summed over the iterations,
peak RSS, and the physics' own profile: MuJoCo's timers, contacts and solver iterations per physics step,
taken afterwards on the same slots stepped serially with a timer callback installed (so the timed
iterations run without it). Measure on an idle machine; under load only the fractions compare.
"""

from __future__ import annotations

import platform
import resource
import time

PROFILE_CONTROL_STEPS = 5  # control steps per slot for the MuJoCo profile


def mujoco_profile(env, control_steps: int = PROFILE_CONTROL_STEPS) -> dict:
    """MuJoCo timers (share of mj_step), mean contacts and solver iterations per physics step, over
    ``control_steps`` control periods of every slot at its current state and controls (B slots of ``env``)."""
    import mujoco
    import numpy as np

    t = mujoco.mjtTimer
    # position (kinematics, inertia, collision, constraint making), velocity, actuation, constraint solver, integration;
    # collision is part of position and listed with its broad/narrow phases as well
    keys = {"position": t.mjTIMER_POSITION, "collision": t.mjTIMER_POS_COLLISION, "collision_broad": t.mjTIMER_COL_BROAD,
            "collision_narrow": t.mjTIMER_COL_NARROW, "velocity": t.mjTIMER_VELOCITY, "actuation": t.mjTIMER_ACTUATION,
            "constraint_solver": t.mjTIMER_CONSTRAINT, "advance": t.mjTIMER_ADVANCE}
    total = {k: 0.0 for k in keys}
    step_s, contacts, solver_iters, n = 0.0, [], [], 0
    substeps = env.cfg.contract.episode.substeps
    mujoco.set_mjcb_time(lambda: time.perf_counter() * 1e6)  # microseconds, as MuJoCo's own timers report
    try:
        for s in env.slots:
            for k in keys.values():
                s.data.timer[k].duration = 0.0
            s.data.timer[mujoco.mjtTimer.mjTIMER_STEP].duration = 0.0
            for _ in range(control_steps * substeps):
                mujoco.mj_step(s.model, s.data)
                contacts.append(s.data.ncon)
                solver_iters.append(int(s.data.solver_niter[0]))
                n += 1
            step_s += s.data.timer[mujoco.mjtTimer.mjTIMER_STEP].duration
            for name, k in keys.items():
                total[name] += s.data.timer[k].duration
    finally:
        mujoco.set_mjcb_time(None)
    return dict(physics_steps=n, share_of_mj_step={k: round(v / max(step_s, 1e-12), 3) for k, v in total.items()},
                mean_contacts=round(float(np.mean(contacts)), 2), mean_solver_iterations=round(float(np.mean(solver_iters)), 2),
                us_per_physics_step_with_timers=round(step_s / max(n, 1), 1))


def measure(trainer, iterations: int) -> dict:
    """Run ``iterations`` PPO iterations of ``trainer`` (a fresh :class:`dgz_cli.rl.runner.Trainer`) and
    report throughput, the wall-clock split, peak RSS and the MuJoCo profile."""
    import torch

    cfg, env = trainer.cfg, trainer.env
    t0 = time.perf_counter()
    try:
        obs = env.reset(cfg.seed)
        for _ in range(iterations):
            obs = trainer.iterate(obs)
        wall = time.perf_counter() - t0
        rows = trainer.history[-iterations:]
        profile = mujoco_profile(env)
    finally:
        env.close()
    split = {k: round(sum(r[k] for r in rows), 4) for k in ("physics_s", "env_other_s", "policy_forward_s", "ppo_update_s")}
    transitions = iterations * cfg.steps_per_env * env.B
    return dict(
        benchmark="train", hands=list(cfg.hands), objects=cfg.objects, envs=env.B, steps_per_env=cfg.steps_per_env,
        iterations=iterations, transitions=transitions, wall_s=round(wall, 4),
        transitions_per_s=round(transitions / wall, 1),
        split_s=split, split_fraction={k: round(v / wall, 3) for k, v in split.items()},
        physics_dt=env.cfg.contract.episode.physics_dt, ppo_epochs=cfg.ppo.num_epochs,
        ppo_mini_batches=cfg.ppo.num_mini_batches, physics_threads=cfg.threads, torch_threads=cfg.torch_threads,
        peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        mujoco=profile, torch=torch.__version__, python=platform.python_version(), machine=platform.machine(),
    )
