"""Typed, frozen configuration of the grasping environment (paper Sec. III-C, IV-A, Supp. S2)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class RewardWeights(_Frozen):
    dis: float = 0.3
    contact: float = 1.0
    force: float = 0.5
    reg: float = 1.5
    pen: float = 0.3
    lift: float = Field(0.0, description="not in the paper (0 reproduces it): weight of r_lift, the object's rise "
                                         "over the lift and hold phases as a fraction of lift_height")


class EnvConfig(_Frozen):
    """Defaults are the paper's protocol; lengths in m, times in s, angles in rad, forces in N."""

    physics_dt: float = Field(0.0025, description="400 Hz physics")
    control_hz: float = Field(20.0, description="policy rate")
    grasp_steps: int = 120
    lift_steps: int = 30
    hold_s: float = Field(2.0, description="hold time of the success criterion")
    lift_height: float = Field(0.5, description="wrist lift over the lift phase; success needs the object to follow")
    success_fraction: float = Field(0.8, description="object must stay ≥ this × lift_height above its start")
    approach_distance: float = Field(0.3, description="palm centre → object centre at reset")
    approach_cone: float = Field(0.5, description="max tilt (rad) of the approach direction from vertical")
    settle_s: float = Field(0.3, description="object settles on the table before the episode starts")
    action_mode: Literal["primitive", "joint"] = "primitive"
    finger_action_scale: float = 0.015
    wrist_action_scale: float = 0.01
    finger_kp: float = Field(3.0, description="N·m/rad, the same for every hand")
    joint_armature: float = Field(0.001, description="kg·m², added to every hand joint (motor inertia)")
    wrist_max_lead: float = Field(0.01, description="wrist targets stay within this (m, rad) of the wrist joints")
    impratio: float = Field(10.0, description="MuJoCo frictional-to-normal impedance ratio (elliptic cones)")
    wrist_kp_lin: float = 2000.0
    wrist_kp_ang: float = 100.0
    point_cloud: int = Field(256, description="object surface points for the node → surface vectors")
    force_scale: float = Field(10.0, description="contact forces are observed as f / force_scale, clipped to [0, 5]")
    force_threshold: float = Field(1.0, description="f0 of r_force in units of force_scale")
    distance_clip: float = Field(0.3, description="node → surface vectors are clipped to this norm and divided by it")
    reward: RewardWeights = RewardWeights()

    @property
    def substeps(self) -> int:
        return int(round(1.0 / (self.control_hz * self.physics_dt)))

    @property
    def hold_steps(self) -> int:
        return int(round(self.hold_s * self.control_hz))

    @property
    def episode_steps(self) -> int:
        return self.grasp_steps + self.lift_steps + self.hold_steps
