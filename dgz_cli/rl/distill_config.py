"""Typed, frozen configuration of `dgz distill` (the one source of its defaults; the CLI reads them from here)
and the student section of a checkpoint manifest (:class:`StudentMeta`)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from dgz_cli.policy.student_config import StudentConfig
from dgz_cli.spec.contract import ObservationLayout
from dgz_cli.spec.envconfig import MAX_SETTLE_S
from dgz_cli.spec.hardware_view import HARDWARE, HardwareView

DEFAULT_HANDS = ("allegro", "shadow", "schunk_svh", "ability")


class DistillConfig(BaseModel):
    """DAgger behaviour cloning of a teacher checkpoint into a student (:mod:`dgz_cli.rl.distill`), then
    optional PPO fine-tuning of the student (the teacher's PPO settings)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    teacher: str = Field(description="the teacher: a checkpoint folder or a name under policies/")
    hands: tuple[str, ...] = Field(DEFAULT_HANDS, description="hands the student is distilled on: shipped names, spec files, "
                                  "generated:DIR (every NAME.urdf in DIR, as dgz train)")
    objects: str = Field("ycb45", description="ycb45, primitives, or comma-separated object names")
    repeat: int = Field(1, ge=1, le=100, description="N_env = hands × objects × repeat")
    iterations: int = Field(10, ge=1, le=10**6, description="DAgger iterations: roll out the student, label "
                            "with the teacher, aggregate, fit")
    steps_per_env: int = Field(190, ge=1, le=10**5, description="control steps per env per DAgger iteration "
                               "(190 = one whole episode of the default contract)")
    epochs: int = Field(4, ge=1, le=1000, description="passes over the aggregated data per DAgger iteration")
    buffer_iterations: int = Field(4, ge=1, le=1000, description="DAgger keeps the data of this many latest "
                                   "iterations (bounds memory)")
    mini_batch: int = Field(1024, ge=16, le=1 << 20)
    learning_rate: float = Field(1e-4, gt=0, le=1, description="Adam, behaviour cloning (small: the student "
                                 "starts at the teacher)")
    max_grad_norm: float = Field(0.5, gt=0, le=1e3)
    finetune_iterations: int = Field(0, ge=0, le=10**7, description="PPO iterations after the DAgger ones")
    finetune_learning_rate: float = Field(2e-5, gt=0, le=1, description="PPO's starting learning rate "
                                          "(the teacher's adaptive-KL schedule adapts it)")
    finetune_steps_per_env: int = Field(130, ge=1, le=10**5)
    checkpoint_every: int = Field(1, ge=1, description="iterations between checkpoints")
    seed: int = Field(0, ge=0, lt=2**32)
    threads: int = Field(2, ge=1, le=256, description="physics worker threads")
    torch_threads: int = Field(1, ge=1, le=256, description="torch threads for the fit (rollouts use 1)")
    view: HardwareView = Field(HARDWARE, description="what hardware gives, imposed on the student in simulation")
    teacher_view: Literal["sim", "student"] = Field("sim", description="what the teacher labels from: the simulator's "
                                                   "observation (sim), or the student's view plus the teacher's "
                                                   "privileged contact and force (student: for a teacher trained "
                                                   "under that view, dgz train's train_view)")
    settle_s: float | None = Field(None, ge=0, le=MAX_SETTLE_S, description="s the object settles before each episode's first "
                                   "frame (None: the teacher's env)")
    student: StudentConfig = StudentConfig()


class StudentMeta(BaseModel):
    """The student section of a checkpoint manifest (format 3)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    distill: DistillConfig
    teacher_path: str = Field(description="where the teacher was loaded from")
    teacher_weights_sha256: str | None = Field(None, pattern=r"^[0-9a-f]{64}$")
    teacher_iteration: int = Field(ge=0)
    teacher_layout: ObservationLayout = Field(description="the teacher's observation layout (with privileged blocks)")
    dagger_iterations: int = Field(0, ge=0, description="DAgger iterations done")
    finetune_iterations: int = Field(0, ge=0, description="PPO iterations done")
    init: dict[str, int] | None = Field(None, description="tensors copied / partly copied / fresh at initialisation")
