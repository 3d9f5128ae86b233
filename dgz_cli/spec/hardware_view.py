"""What a real hand and camera give a policy, as options the simulator can impose (issue 12).

A distilled student (``dgz distill``) is trained and evaluated in simulation on the observation hardware
gives, not on the simulator's perfect one. :class:`HardwareView` says which of the simulator's advantages
are taken away; it is recorded in the student's checkpoint, and ``dgz eval`` evaluates the student under
it (``dgz_cli.sim.hardware.HardwareViewEnv`` applies it). On a real hand nothing is imposed: the runtime's
observation (:mod:`dgz_cli.runtime.observation`) already is what hardware gives.

* ``joint_noise``: Gaussian noise (std, rad) on every joint reading; the velocity the policy sees is the
  true velocity plus the finite difference of that noise over one control period (hardware velocities are
  finite differences of noisy readings).
* ``held_cloud``: the object point cloud is taken at the first frame of the episode and held (the object
  is assumed static, as in the paper's real-world set-up: the first perception frame is reused); the node
  → surface vectors are measured against it, the grasp target is its centroid, and the object velocities
  are 0 (what the runtime feeds).
* the contract's wrist guidance (if the teacher uses it) needs nothing here: it is computed from the
  observation's target block, so under ``held_cloud`` it steers toward the held centroid, as on hardware.

The privileged blocks (``contact``, ``force``) are not perturbed: a student's observation layout simply has
none (:func:`student_layout`).
"""

from __future__ import annotations

from pydantic import Field

from dgz_cli.spec.contract import PRIVILEGED_BLOCKS, ControlContract, ObservationLayout, _Frozen


class HardwareView(_Frozen):
    """Hardware perturbations of the simulated observation (see the module docstring)."""

    joint_noise: float = Field(0.0, ge=0, le=0.5, description="rad: std of the Gaussian noise on joint readings")
    held_cloud: bool = Field(False, description="the object cloud of the episode's first frame is held; its "
                             "centroid is the target; object velocities are observed as 0")

    @property
    def active(self) -> bool:
        return self.joint_noise > 0 or self.held_cloud

    def describe(self) -> str:
        """One line for progress output and model cards."""
        if not self.active:
            return "none (the simulator's observation)"
        parts = []
        if self.joint_noise > 0:
            parts.append(f"joint noise {self.joint_noise:g} rad")
        if self.held_cloud:
            parts.append("object cloud held from the first frame (centroid target, zero object velocity)")
        return ", ".join(parts)


HARDWARE = HardwareView(joint_noise=0.01, held_cloud=True)  # `dgz distill`'s default


def student_layout(layout: ObservationLayout) -> ObservationLayout:
    """The observation layout without its privileged blocks (same scales, remaining blocks in order)."""
    return layout.model_copy(update=dict(node=tuple(b for b in layout.node if b[0] not in PRIVILEGED_BLOCKS),
                                         global_=tuple(b for b in layout.global_ if b[0] not in PRIVILEGED_BLOCKS)))


def student_contract(contract: ControlContract) -> ControlContract:
    """The teacher's contract for a student: the same actions, episode, guidance and prior; no privileged input."""
    out = contract.model_copy(update=dict(observation=student_layout(contract.observation)))
    return ControlContract.model_validate(out.model_dump(by_alias=True))  # re-validated
