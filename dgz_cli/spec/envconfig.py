"""Typed, frozen configuration of the simulated grasping task (paper Sec. III-C, IV-A, Supp. S2).

What a policy sees and does (observation and action layout, scales, rates, phases) is the control
contract, :class:`dgz_cli.spec.contract.ControlContract`, held here as ``contract``. The rest is how the
simulator realises the task: the start state, the controllers, the contact model and the reward. It lives
in ``spec`` so that checkpoints (``rl``) can record it without importing the simulator.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from dgz_cli.spec.contract import ControlContract, _Frozen


MAX_SETTLE_S = 10.0
"""s: the longest settle an env accepts (`EnvConfig.settle_s`, so also a run's ``settle_s``, `dgz eval --settle`
and `dgz distill --settle`)."""


class RewardWeights(_Frozen):
    dis: float = Field(0.3, ge=0, le=1e3)
    contact: float = Field(1.0, ge=0, le=1e3)
    force: float = Field(0.5, ge=0, le=1e3)
    reg: float = Field(1.5, ge=0, le=1e3)
    pen: float = Field(0.3, ge=0, le=1e3)
    lift: float = Field(0.0, ge=0, le=1e3,
                        description="not in the paper (0 reproduces it): weight of r_lift, the object's rise "
                                    "over the lift and hold phases as a fraction of lift_height")


class GraspXLReward(_Frozen):
    """The reward of GraspXL's code (issue 11), with a lift/hold term and a success bonus for our protocol's
    lift. Terms (each logged): r_dis = −Σ w_i ‖d_i‖ / Σ w_i (fingertips weigh ``tip_weight``), r_contact =
    Σ w_i c_i / Σ w_i, r_force = Σ w_i min(f_i / force_scale, 1) / Σ w_i (positive, capped), r_objvel =
    −‖v_obj − v_palm‖² (the object's velocity relative to the palm; before the lift the palm's is dropped),
    r_lift = clip(rise / lift_height, 0, 1) after the grasp phase, r_success = 1 at the last step of a
    successful episode; r_residual = −mean a² over the policy's active action dims (weight ``residual``,
    0 by default); r_displace = −min(‖p_obj − p_obj,0‖, push_limit) / push_limit during the grasp phase (the
    object's displacement from where it settled; weight ``displace``, 0 by default); pushing the object more
    than ``push_limit`` during the grasp phase ends the episode (a true terminal state) with ``push_penalty``."""

    dis: float = Field(0.3, ge=0, le=1e3)
    contact: float = Field(1.0, ge=0, le=1e3)
    force: float = Field(0.5, ge=0, le=1e3)
    objvel: float = Field(1.5, ge=0, le=1e3)
    lift: float = Field(3.0, ge=0, le=1e3)
    success: float = Field(30.0, ge=0, le=1e4)
    tip_weight: float = Field(4.0, ge=1, le=100)
    push_limit: float = Field(0.3, gt=0, le=10, description="m of object displacement during the grasp phase")
    push_penalty: float = Field(10.0, ge=0, le=1e4)
    residual: float = Field(0.0, ge=0, le=1e3, description="weight of r_residual = −mean a² over the policy's active "
                            "action dims (wrist + mask-enabled primitives), its own action before the prior; "
                            "not GraspXL's (issue 11: a residual that cannot undo the prior cheaply); 0 = off")
    displace: float = Field(0.0, ge=0, le=1e3, description="weight of r_displace, the object's displacement during "
                            "the grasp phase as a fraction of push_limit; not GraspXL's (issue 11: the push limit "
                            "alone ignores the 5–30 cm pushes that eval counts as pushed away); 0 = off")


class EnvConfig(_Frozen):
    """Defaults are the paper's protocol; lengths in m, times in s, angles in rad, forces in N."""

    contract: ControlContract = ControlContract()
    approach_distance: float = Field(0.3, gt=0, description="palm centre → object centre at reset")
    approach_cone: float = Field(0.5, ge=0, description="max tilt (rad) of the approach direction from vertical")
    settle_s: float = Field(0.3, ge=0, le=MAX_SETTLE_S,
                            description="s the object settles on the table before the episode starts")
    object_orientation: Literal["random", "upright"] = Field(
        "random", description="the object's orientation when it is dropped: random, uniform over all rotations; "
                              "upright, the model's own frame (z up, as the YCB scans stand) turned by a uniform yaw "
                              "about the vertical, as GraspXL's and RobustDexGrasp's code place their objects")
    finger_kp: float = Field(3.0, gt=0, description="N·m/rad, the same for every hand")
    joint_armature: float = Field(0.001, ge=0, description="kg·m², added to every hand joint (motor inertia)")
    wrist_max_lead: float = Field(0.01, gt=0, description="wrist targets stay within this (m, rad) of the wrist joints")
    impratio: float = Field(10.0, gt=0, description="MuJoCo frictional-to-normal impedance ratio (elliptic cones)")
    wrist_kp_lin: float = Field(2000.0, gt=0)
    wrist_kp_ang: float = Field(100.0, gt=0)
    force_threshold: float = Field(1.0, ge=0, description="f0 of r_force in units of force_scale")
    reward: RewardWeights = RewardWeights()
    reward_variant: Literal["paper", "graspxl"] = Field(
        "paper", description="paper: the text's terms and weights (reward); graspxl: GraspXL's code (graspxl)")
    graspxl: GraspXLReward = GraspXLReward()
    roll: Literal["uniform", "narrow", "clear"] = Field(
        "uniform", description="the hand's roll about the approach axis at reset: uniform; narrow, the best of "
                               "roll_candidates for closing across the object's narrowest width; clear, the same "
                               "among the candidates whose palm and forearm (the wrist node's collision boxes) stay "
                               "above the table with the grasp point at the guidance target (or, if none does, "
                               "within clearance_slack of the one that comes closest)")
    roll_candidates: int = Field(10, ge=1, le=360)
    clearance_slack: float = Field(0.01, ge=0, description="m: with roll 'clear' and no candidate clearing the "
                                   "table, the candidates this close to the best clearance stay eligible")
    clearance_depth: float = Field(0.0, ge=0, description="m: with roll 'clear', how far below the table the palm "
                                   "and forearm may reach at the guidance target and still count as clearing it "
                                   "(the hand stops on the object before the target)")
    target_noise: float = Field(0.0, ge=0, le=0.1, description="training only (issue 11, a domain randomisation): "
                                "m, std of a Gaussian offset drawn per episode on each horizontal world axis and "
                                "added to the grasp target (the observed cloud centroid the guidance steers to), so "
                                "a fixed wrist offset stops paying and the object's surface has to be read; rewards "
                                "and success use the true state; dgz eval and deploy turn it off")
    dynamics_noise: float = Field(0.0, ge=0, le=1.0, description="training only (issue 11, a domain "
                                  "randomisation): half-width r of a log-uniform scale in [e^-r, e^r] drawn per "
                                  "episode and slot, one each for the object's mass (and inertia), the contact "
                                  "friction (every geom's) and the finger actuators' force limits; each slot then "
                                  "has its own copy of the compiled model; dgz eval and deploy turn it off")
    early_stop: bool = Field(False, description="training only (issue 11, throughput): end an episode as a true "
                             "terminal state once it can no longer succeed — nothing touched by the end of the grasp "
                             "phase, or the object not up when the hold starts or dropped during it; dgz eval and "
                             "the MuJoCo deploy backend always run the full protocol")
