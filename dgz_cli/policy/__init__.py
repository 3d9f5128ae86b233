"""MAGCN policy network. Imports only ``dgz_cli.spec`` (plus torch/numpy). Import submodules directly
(``dgz_cli.policy.magcn``, ``dgz_cli.policy.presets``, …); this package imports nothing, so configs load
without torch."""
