"""Deploy runtime: safety filter, wrist Kalman filter, fixed-rate loop, step log and replay, and what a trained
policy needs on hardware (forward kinematics, the observation builder, the contract's start pose).

A higher layer: composes :mod:`dgz_cli.hw` (hand drivers, arm interfaces) with policies; may import
:mod:`dgz_cli.sim` (feature functions, static graph) and :mod:`dgz_cli.policy` / :mod:`dgz_cli.rl` (checkpoints).
torch and mujoco are imported inside functions only, so ``dgz --help`` stays instant.
"""
