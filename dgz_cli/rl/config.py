"""Typed, frozen run configuration of `dgz train`: the one source of its defaults (the CLI reads them
from here) and saved verbatim into every checkpoint."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic_core import PydanticCustomError

from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ActionLayout, ClosingPrior,
                                   ControlContract, EpisodeProtocol, ObservationLayout, StartPose,
                                   WristGuidance, check_translation_factors)
from dgz_cli.spec.envconfig import MAX_SETTLE_S, EnvConfig, GraspXLReward, RewardWeights
from dgz_cli.spec.hardware_view import HardwareView

ABLATIONS = ("full", "no_physical", "early_fusion", "no_primitives", "no_mask")


class PPOConfig(BaseModel):
    """Defaults follow the paper's Table S1 (γ 0.996, λ 0.95, ε 0.2, Adam 5e-4 with adaptive KL, grad-norm
    0.5, 4 epochs × 4 mini-batches); the value-loss coefficient, entropy coefficient, desired KL and
    advantage normalization are not given by the paper and follow rsl_rl."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    gamma: float = Field(0.996, ge=0, le=1)
    lam: float = Field(0.95, ge=0, le=1)
    clip_param: float = Field(0.2, gt=0, le=10)
    learning_rate: float = Field(5e-4, gt=0, le=1)
    schedule: Literal["adaptive", "fixed"] = "adaptive"
    desired_kl: float = Field(0.01, gt=0, le=10)
    min_lr: float = Field(1e-5, gt=0, le=1)
    max_lr: float = Field(1e-2, gt=0, le=1)
    max_grad_norm: float = Field(0.5, gt=0, le=1e3)
    num_epochs: int = Field(4, gt=0, le=100)
    num_mini_batches: int = Field(4, gt=0, le=1024)
    value_loss_coef: float = Field(1.0, ge=0, le=1e3)
    entropy_coef: float = Field(0.0, ge=0, le=10)
    use_clipped_value_loss: bool = True
    normalize_advantages: bool = True
    min_std: float = Field(0.0, ge=0, le=10, description="exploration floor: the policy's std is kept ≥ this "
                           "after every step (GraspXL: 0.2); 0 = none")
    max_std: float = Field(0.0, ge=0, le=10, description="exploration ceiling: the policy's std is kept ≤ this from "
                           "the first rollout on (a fine-tune can lower its checkpoint's exploration); 0 = none")

    @model_validator(mode="after")
    def _std_bounds_ordered(self):
        if self.min_std > 0 and self.max_std > 0 and self.min_std > self.max_std:
            raise ValueError(f"min_std {self.min_std:g} is above max_std {self.max_std:g}")
        return self


class TrainConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    hands: tuple[str, ...] = Field(("allegro", "shadow", "schunk_svh", "ability"), description="training hands")
    objects: str = Field("ycb45", description="ycb45, primitives, or comma-separated object names")
    repeat: int = Field(3, ge=1, le=100, description="N_env = hands × objects × repeat (paper: 3)")
    preset: str = Field("compact", description="network size: compact (CPU) or paper")
    ablation: Literal[ABLATIONS] = Field("full", description="Table I variant: " + ", ".join(ABLATIONS) + " (no_mask "
                                         "also turns mask_actions off: without the mask every dimension is an action)")
    iterations: int = Field(100, ge=1, le=10**7, description="PPO updates")
    steps_per_env: int = Field(130, ge=1, le=10**5, description="transitions per env per PPO update (paper: 130)")
    checkpoint_every: int = Field(5, ge=1, description="iterations between checkpoints")
    seed: int = Field(0, ge=0, lt=2**32)
    threads: int = Field(2, ge=1, le=256, description="physics worker threads")
    torch_threads: int = Field(1, ge=1, le=256, description="torch threads for the PPO update (rollouts always use 1)")
    bc_episodes: int = Field(0, ge=0, le=1000, description="behaviour-cloning warm start: scripted episodes per env "
                                                           "before PPO (0 = from scratch, as in the paper)")
    bc_epochs: int = Field(10, ge=1, le=1000, description="epochs of the behaviour-cloning regression")
    bc_dagger_rounds: int = Field(0, ge=0, le=100, description="DAgger rounds after the first fit: the clone acts, "
                                                               "the scripted grasp labels, the data are aggregated and refit")
    bc_log_std: float = Field(-1.5, ge=-10, le=2, description="exploration log-std set after behaviour cloning")
    bc_learning_rate: float = Field(2e-5, gt=0, le=1, description="PPO's starting learning rate after behaviour "
                                    "cloning (the adaptive-KL schedule adapts it; 5e-4 undoes the clone in a few steps)")
    lift_weight: float = Field(0.0, ge=0, le=1e3, description="weight of r_lift (not in the paper; 0 = the paper's reward)")
    reward: Literal["paper", "graspxl"] = Field("paper", description="reward variant: the paper's text or "
                                                "GraspXL's code (see docs/training.md)")
    guidance_gain: float = Field(0.0, ge=0, le=1, description="wrist guidance gain toward the object centroid "
                                 "(0 = off: the policy moves the wrist alone, as in the paper's text)")
    guidance_stop_gap: float | None = Field(None, gt=0, le=0.25, description="m: the guidance stops moving the palm "
                                            "toward the object along its normal once the palm is this close to the "
                                            "surface (contract guidance.stop_gap; None = it presses on)")
    guidance_aim_residual: float | None = Field(None, gt=0, le=0.2, description="m per unit: the policy's wrist "
                                                "translation action shifts the guidance's aim instead of moving the "
                                                "wrist (contract guidance.aim_residual; needs guidance_gain > 0; "
                                                "None = it is a velocity)")
    guidance_aim_axes: tuple[bool, bool, bool] = Field((True, True, True), description="the palm axes (f, l, n) "
                                                       "whose translation action is an aim shift under "
                                                       "guidance_aim_residual; the others stay velocities (contract "
                                                       "guidance.aim_axes)")
    roll: Literal["uniform", "narrow", "clear"] = Field("uniform", description="start roll: uniform, closing "
                                                        "across the object's narrowest width (narrow), or that "
                                                        "among the rolls whose hand clears the table (clear)")
    observation: Literal["paper", "markov"] = Field("paper", description="observation layout: the paper's, or "
                                                    "with finger PD error, guidance error and episode phase")
    finger_max_lead: float | None = Field(None, gt=0, le=10, description="rad a finger target may lead its joint "
                                          "(None = no cap)")
    mask_actions: bool = Field(False, description="score only the primitives the activation mask enables")
    log_std_per_type: bool = Field(False, description="exploration log-std per (node type, primitive)")
    closing_prior: bool = Field(False, description="the policy is a residual on the contract's Markov closing prior "
                                "(needs observation: markov)")
    prior_close_guide: float | None = Field(None, gt=0, le=0.3, description="m: the closing prior also closes once "
                                            "the guidance error is below this (contract prior.close_guide; None = off)")
    prior_close_step: int = Field(50, ge=0, description="control step from which the closing prior closes regardless")
    wrist_residual: float = Field(1.0, ge=0, le=1, description="factor on the policy's wrist action (contract "
                                  "action.wrist_residual; 0: the wrist follows the guidance and the lift alone)")
    finger_residual: float = Field(1.0, ge=0, le=1, description="factor on the policy's finger actions before the "
                                   "closing prior is added (contract action.finger_residual)")
    wrist_translation_residual: float | tuple[float, float, float] | None = Field(
        None, description="factor in [0, 1] on the policy's wrist translation actions alone, one for all three palm "
                          "axes or one per axis (f, l, n) (contract action.wrist_translation_residual; None = "
                          "wrist_residual)")
    residual_weight: float = Field(0.0, ge=0, le=1e3, description="graspxl reward: weight of −mean a² over the "
                                   "policy's active action dims (its residual on the prior; 0 = off)")
    displace_weight: float = Field(0.0, ge=0, le=1e3, description="graspxl reward: weight of −(the object's "
                                   "displacement during the grasp phase / push_limit) (0 = off)")
    critic: Literal["shared", "separate"] = Field("shared", description="value head on the actor's trunk (the "
                                                  "paper), or a separate small critic (its own 32×4 GCN trunk)")
    critic_warmup: int = Field(0, ge=0, le=100, description="the run's first iterations fit the value alone (the "
                               "actor, a shared trunk included, does not move): for fine-tuning a checkpoint whose "
                               "critic does not match its actor, e.g. one whose actions were cloned")
    failure_priority: float | None = Field(None, gt=0, le=10, description="prioritised sampling of failing (hand, "
                                           "object) pairs: PPO mini-batches draw an env's transitions ∝ (1 − its pair's "
                                           "success EMA) + this floor; None = uniform")
    early_stop: bool = Field(False, description="end training episodes that can no longer succeed (eval keeps the "
                             "full protocol)")
    target_noise: float = Field(0.0, ge=0, le=0.1, description="m: std of a per-episode horizontal offset on the "
                                "grasp target the guidance steers to and the policy observes (training only; env "
                                "target_noise; 0 = off)")
    dynamics_noise: float = Field(0.0, ge=0, le=1.0, description="r: per episode the object's mass, the contact "
                                  "friction and the finger force limits are each scaled by a log-uniform factor in "
                                  "[e^-r, e^r] (training only; env dynamics_noise; 0 = off)")
    settle_s: float = Field(0.3, ge=0, le=MAX_SETTLE_S, description="s the object settles on the table before each episode's "
                            "first frame (env settle_s; dgz eval --settle sets it for evaluation)")
    train_view: HardwareView | None = Field(None, description="training only: the policy is trained on the observation "
                                            "hardware gives (spec.hardware_view: the first frame's object cloud held, "
                                            "its centroid the guidance's target, object velocities 0; joint noise) and "
                                            "keeps its privileged contact and force inputs; rewards use the true state; "
                                            "dgz eval and deploy use the sim's view; dgz distill --teacher-view student "
                                            "labels with it; "
                                            "None = the sim's view")
    object_orientation: Literal["random", "upright"] = Field("random", description="the object's orientation when "
                                                             "dropped: random (all rotations) or upright (its model's "
                                                             "frame, uniform yaw; env object_orientation)")
    physics_hz: float = Field(400.0, ge=20, le=2000, description="physics rate of the training env (the paper: 400; "
                              "200 halves the physics cost)")
    thumb_open: float = Field(0.0, ge=0, le=1, description="start pose: the thumb's opening joints this fraction of "
                              "the way to their + limit (contract start.thumb_open; 1 = the paper's pre-grasp)")
    thumb_open_primitives: tuple[Literal["ABD", "ROT"], ...] = Field(("ABD",), min_length=1, description="the "
                                                                     "thumb's opening joints (contract start.thumb_primitives)")
    init_log_std: float | None = Field(None, ge=-10, le=2, description="initial exploration log-std (None: the preset's)")
    init_from: str | None = Field(None, min_length=1, description="fine-tune: a checkpoint folder or shipped policy "
                                  "whose weights and return scale start the run (same model and control contract, "
                                  "but for the residual factors and the guidance's stop gap, aim residual and "
                                  "aim axes, whose changes rescale the actor so that it starts with the checkpoint's "
                                  "commands; None = a fresh network)")
    ppo: PPOConfig = PPOConfig()

    @field_validator("physics_hz")
    @classmethod
    def _whole_substeps(cls, v: float) -> float:
        control_hz = EpisodeProtocol().control_hz
        if abs(v / control_hz - round(v / control_hz)) > 1e-9:
            raise ValueError(f"must be a whole multiple of the {control_hz:g} Hz control rate (e.g. 200 or 400)")
        return v

    @property
    def observed_view(self) -> HardwareView | None:
        """The hardware view the training env imposes, or None when it observes as the simulator does (no
        ``train_view``, or one that perturbs nothing)."""
        return self.train_view if self.train_view is not None and self.train_view.active else None

    @field_validator("wrist_translation_residual")
    @classmethod
    def _translation_factors(cls, v):
        return check_translation_factors(v)

    @model_validator(mode="after")
    def _one_warm_start(self) -> "TrainConfig":
        if self.init_from is not None and self.bc_episodes > 0:
            raise ValueError("init_from and bc_episodes are two warm starts; give one of them")
        return self

    @model_validator(mode="after")
    def _valid_contract(self) -> "TrainConfig":
        """The control contract's own cross-field rules (e.g. the closing prior reads the markov layout's phase,
        an aim residual needs the guidance) hold for the contract this config builds, so a config that breaks
        them fails where every other config error does, not later while the env is built."""
        try:
            env_config(self)
        except ValidationError as exc:
            # the contract's message as written (no second "Value error, " prefix), as spec.models does
            raise PydanticCustomError("contract", exc.errors()[0]["msg"].removeprefix("Value error, ")) from None
        return self


def env_config(cfg: TrainConfig) -> EnvConfig:
    """The env a run config asks for: the one place a TrainConfig becomes a control contract, a reward and a
    start-state protocol. ``dgz train`` builds its env from it and ``dgz eval --policy scripted`` its
    ``--guidance``/``--roll``/``--physics-hz``/``--thumb-open`` env, so both agree on the same options by construction."""
    mode = "joint" if cfg.ablation == "no_primitives" else "primitive"
    layout = (ObservationLayout() if cfg.observation == "paper"
              else ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS))
    contract = ControlContract(observation=layout,
                               action=ActionLayout(mode=mode, finger_max_lead=cfg.finger_max_lead,
                                                   mask_actions=cfg.mask_actions and cfg.ablation != "no_mask",
                                                   wrist_residual=cfg.wrist_residual,
                                                   finger_residual=cfg.finger_residual,
                                                   wrist_translation_residual=cfg.wrist_translation_residual),
                               episode=EpisodeProtocol(physics_dt=1.0 / cfg.physics_hz),
                               guidance=WristGuidance(gain=cfg.guidance_gain, stop_gap=cfg.guidance_stop_gap,
                                                      aim_residual=cfg.guidance_aim_residual,
                                                      aim_axes=cfg.guidance_aim_axes),
                               prior=ClosingPrior(enabled=cfg.closing_prior, close_step=cfg.prior_close_step,
                                                  close_guide=cfg.prior_close_guide),
                               start=StartPose(thumb_open=cfg.thumb_open, thumb_primitives=cfg.thumb_open_primitives))
    return EnvConfig(contract=contract, reward=RewardWeights(lift=cfg.lift_weight), reward_variant=cfg.reward,
                     graspxl=GraspXLReward(residual=cfg.residual_weight, displace=cfg.displace_weight),
                     roll=cfg.roll, early_stop=cfg.early_stop, target_noise=cfg.target_noise, settle_s=cfg.settle_s,
                     object_orientation=cfg.object_orientation, dynamics_noise=cfg.dynamics_noise)
