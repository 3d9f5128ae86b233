"""Adaptive-KL learning-rate schedule (as in rsl_rl's PPO, ``schedule="adaptive"``)."""

from __future__ import annotations


class AdaptiveKLSchedule:
    """After each mini-batch, compare the mean KL(old ‖ new) with ``desired_kl``:

    * ``kl > 2·desired_kl``            → ``lr = max(min_lr, lr / factor)``
    * ``0 < kl < desired_kl / 2``      → ``lr = min(max_lr, lr · factor)``
    * otherwise                        → unchanged (the thresholds themselves leave lr unchanged).
    """

    def __init__(self, lr: float = 5e-4, desired_kl: float = 0.01, min_lr: float = 1e-5, max_lr: float = 1e-2,
                 factor: float = 1.5) -> None:
        if not (0 < min_lr <= max_lr) or desired_kl <= 0 or factor <= 1:
            raise ValueError("need 0 < min_lr <= max_lr, desired_kl > 0 and factor > 1")
        self.lr, self.desired_kl, self.min_lr, self.max_lr, self.factor = float(lr), desired_kl, min_lr, max_lr, factor

    def step(self, kl: float) -> float:
        """Update and return the learning rate for the observed mean KL."""
        if kl > 2.0 * self.desired_kl:
            self.lr = max(self.min_lr, self.lr / self.factor)
        elif 0.0 < kl < 0.5 * self.desired_kl:
            self.lr = min(self.max_lr, self.lr * self.factor)
        return self.lr
