"""PPO training pieces for graph policies. May import ``dgz_cli.policy`` and ``dgz_cli.spec``, never the
simulator: the runner receives its env from the composition root (the CLI). Import submodules directly
(``dgz_cli.rl.ppo``, ``dgz_cli.rl.config``, …); this package imports nothing, so configs load without torch."""
