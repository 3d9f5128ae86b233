"""MAGCN policy network. Imports only ``dgz_cli.spec`` (plus torch/numpy)."""

from dgz_cli.policy.graph import OBS_KEYS, action_valid, masked_mean, normalized_adjacency, to_tensors
from dgz_cli.policy.magcn import (MAGCN, flops_per_graph, gaussian_entropy, gaussian_kl, gaussian_log_prob,
                                  parameter_count)
from dgz_cli.policy.presets import PRESETS, MagcnConfig, get_preset

__all__ = ["MAGCN", "MagcnConfig", "OBS_KEYS", "PRESETS", "action_valid", "flops_per_graph", "gaussian_entropy",
           "gaussian_kl", "gaussian_log_prob", "get_preset", "masked_mean", "normalized_adjacency",
           "parameter_count", "to_tensors"]
