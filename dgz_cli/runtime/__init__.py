"""Deploy runtime: safety filter, wrist Kalman filter, fixed-rate loop, step log and replay.

Composes :mod:`dgz_cli.hw` (drivers) with a policy given by reference; never imports sim or training code.
"""
