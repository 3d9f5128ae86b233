"""Typed, frozen training configuration (`dgz train`); saved verbatim into every checkpoint."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class TrainConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    hands: tuple[str, ...] = ("allegro", "shadow", "schunk_svh", "ability")
    objects: str = Field("ycb45", description="ycb45, primitives, or comma-separated object names")
    repeat: int = Field(3, ge=1, description="N_env = hands × objects × repeat (paper: 3)")
    preset: str = "compact"
    ablation: Literal["full", "no_physical", "early_fusion", "no_primitives", "no_mask"] = "full"
    iterations: int = Field(100, ge=1)
    steps_per_env: int = Field(130, ge=1, description="transitions per env per PPO update (paper: 130)")
    checkpoint_every: int = Field(5, ge=1, description="iterations between checkpoints")
    seed: int = 0
    threads: int = Field(2, ge=1, description="physics worker threads")
    torch_threads: int = Field(1, ge=1, description="torch threads for the PPO update (rollouts always use 1)")
    bc_episodes: int = Field(0, ge=0, description="behaviour-cloning warm start: scripted episodes per env before "
                                                  "PPO (0 = from scratch, as in the paper)")
    bc_epochs: int = Field(10, ge=1, description="epochs of the behaviour-cloning regression")
    bc_dagger_rounds: int = Field(0, ge=0, description="DAgger rounds after the first fit: the clone acts, the "
                                                       "scripted grasp labels, the data are aggregated and refit")
    bc_log_std: float = Field(-1.5, description="exploration log-std set after behaviour cloning")
    bc_learning_rate: float = Field(2e-5, gt=0, description="PPO's starting learning rate after behaviour cloning "
                                    "(the adaptive-KL schedule adapts it; 5e-4 undoes the clone in a few steps)")
    lift_weight: float = Field(0.0, ge=0, description="weight of r_lift (not in the paper; 0 = the paper's reward)")
