"""PPO training pieces for graph policies. May import ``dgz_cli.policy`` (and ``dgz_cli.spec``)."""

from dgz_cli.rl.ppo import PPO, PPOConfig
from dgz_cli.rl.schedule import AdaptiveKLSchedule
from dgz_cli.rl.storage import STATIC_KEYS, MiniBatch, RolloutStorage

__all__ = ["PPO", "PPOConfig", "AdaptiveKLSchedule", "MiniBatch", "RolloutStorage", "STATIC_KEYS"]
