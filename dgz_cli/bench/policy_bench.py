"""`dgz bench policy`: MAGCN latency/throughput, PPO update speed, env+policy rollout speed."""

from __future__ import annotations

import resource
import statistics
import time


def _obs(b: int, n: int):
    import torch

    adj = torch.zeros(b, n, n)
    for j in range(1, n):  # a chain-ish tree: node j hangs off node (j-1)//2
        adj[:, (j - 1) // 2, j] = 1.0
    nodes = torch.randn(b, n, 23)
    nodes[:, :, 17:] = 0.0
    nodes[:, 0, 17] = 1.0
    return {"nodes": nodes, "global": torch.randn(b, 16), "adjacency": adj, "physical": torch.randn(b, n, 27).clamp(-1, 1),
            "mask": (torch.rand(b, n, 3) > 0.5).float(), "node_valid": torch.ones(b, n, dtype=torch.bool)}


def run(preset: str, nodes: int = 20, threads: int = 1) -> dict:
    import numpy as np
    import torch

    from dgz_cli.policy.magcn import MAGCN, flops_per_graph, parameter_count
    from dgz_cli.policy.presets import get_preset
    from dgz_cli.rl.ppo import PPO
    from dgz_cli.rl.storage import RolloutStorage
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    torch.set_num_threads(threads)
    torch.manual_seed(0)
    cfg = get_preset(preset)
    model = MAGCN(cfg).eval()
    one = _obs(1, nodes)
    lat = []
    with torch.no_grad():
        for _ in range(20):
            model(one)
        for _ in range(200):
            t = time.perf_counter()
            model(one)
            lat.append(time.perf_counter() - t)
    big = _obs(1024, nodes)
    with torch.no_grad():
        model(big)
        t = time.perf_counter()
        for _ in range(3):
            model(big)
        fwd_rate = 3 * 1024 / (time.perf_counter() - t)

    steps, envs = 32, 64
    storage = RolloutStorage(steps, envs, _obs(envs, nodes), 6 + 3 * nodes, seed=0)
    ppo = PPO(model)
    static = _obs(envs, nodes)
    for _ in range(steps):
        o = dict(static, nodes=torch.randn(envs, nodes, 23), **{"global": torch.randn(envs, 16)})
        out = ppo.act(o)
        storage.add(o, reward=torch.randn(envs), terminated=torch.zeros(envs, dtype=torch.bool),
                    truncated=torch.zeros(envs, dtype=torch.bool), **out)
    model.train()
    t = time.perf_counter()
    ppo.update(storage, torch.zeros(envs))
    update_rate = steps * envs * ppo.cfg.num_epochs / (time.perf_counter() - t)

    from dgz_cli.policy.graph import to_tensors

    tri = load_spec(resolve_spec("dgz_tri"))
    env = GraspEnv([(tri, o) for o in resolve_objects("primitives")] * 4, seed=0, threads=2)
    obs = env.reset(0)
    model.eval()
    torch.set_num_threads(1)
    t = time.perf_counter()
    n_steps = 50
    for _ in range(n_steps):
        with torch.no_grad():
            action = model(to_tensors(obs))[0].numpy()
        obs, *_ = env.step(np.clip(action, -1, 1))
    rollout_rate = n_steps * env.B / (time.perf_counter() - t)
    env.close()
    return dict(
        benchmark="policy", preset=preset, nodes=nodes, torch_threads=threads,
        parameters=parameter_count(cfg), mflop_per_graph=round(flops_per_graph(cfg, nodes) / 1e6, 2),
        batch1_forward_ms=round(1000 * statistics.median(lat), 3), batch1_forward_p99_ms=round(1000 * float(np.percentile(lat, 99)), 3),
        forward_graphs_per_s_b1024=round(fwd_rate, 1), ppo_update_samples_per_s=round(update_rate, 1),
        rollout_env_steps_per_s=round(rollout_rate, 1), rollout_envs=16, rollout_hand="dgz_tri",
        peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    )
