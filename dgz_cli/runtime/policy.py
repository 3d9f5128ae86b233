"""Policies the runtime drives, and how ``--policy`` names them.

Every policy outputs normalized actions in the control contract's layout (see :class:`.types.Policy`).

* ``scripted``: the spec-only scripted grasp of :mod:`dgz_cli.sim.scripted` (the one ``dgz eval --policy
  scripted`` runs), on the observation a real hand gives (:class:`.observation.HardwareObservation`, which
  needs the object's points).
* ``close``: a blind close (+FLEX on every active node for ``close_steps``, then hold) for bring-up without
  an object.
* a checkpoint folder or a name under ``policies/`` (:mod:`.trained`; torch is imported only then);
* ``package.module:factory``, called with the HandSpec.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from dgz_cli.runtime.types import StepInput, check_privileged
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec

BUILTIN = ("scripted", "close")


class ProprioObservation:
    """Default builder for policies without their own: proprioception plus the grasp target point (object
    centroid, palm frame at the start) if known."""

    def reset(self, spec: HandSpec, context: dict) -> None:
        self.spec = spec
        pts = context.get("object_points")
        self.object_point = None if pts is None else np.asarray(pts, dtype=float).reshape(-1, 3).mean(axis=0)

    def build(self, step: StepInput) -> dict:
        s = step.state
        return {"step": step.k, "q": None if s is None else s.q, "effort": None if s is None else s.effort,
                "target": step.target, "last_action": step.last_action, "wrist_command": step.wrist_command,
                "object_point": self.object_point}


class ClosePolicy:
    """No wrist motion and +FLEX at ``flex`` (normalized) on every node whose FLEX is active, for
    ``close_steps`` steps, then zeros (hold)."""

    name = "close"
    privileged_inputs = frozenset()

    def __init__(self, spec: HandSpec, contract: ControlContract = ControlContract(), flex: float = 2.0 / 3.0,
                 close_steps: int = 130) -> None:
        act = contract.action
        self.contract, self.flex, self.close_steps = contract, flex, close_steps
        self.action_dim = act.dim(len(spec.nodes))
        self.flex_cols = [act.wrist_dim + act.n_prim * i for i, n in enumerate(spec.nodes)
                          if spec.activation_mask.get(n.id, [0, 0, 0])[0]]
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def act(self, observation: Any) -> np.ndarray:
        a = np.zeros(self.action_dim)
        if self.k < self.close_steps:
            a[self.flex_cols] = self.flex
        self.k += 1
        return a


class ScriptedPolicy:
    """The simulator's scripted grasp (:class:`dgz_cli.sim.scripted.ScriptedGrasp`) for one hand, acting on
    the observation its builder gives (``observation_builder``: a :class:`HardwareObservation` on hardware,
    the simulator's own observation on the MuJoCo backend)."""

    name = "scripted"
    privileged_inputs = frozenset()

    def __init__(self, spec: HandSpec, grasp_offset: np.ndarray, contract: ControlContract, observation_builder) -> None:
        from dgz_cli.sim.scripted import ScriptedGrasp

        self.contract, self.observation_builder = contract, observation_builder
        self.grasp = ScriptedGrasp(len(spec.nodes), np.asarray(grasp_offset, dtype=float).reshape(1, 3), contract)

    def reset(self) -> None:
        self.grasp.reset(None)

    def act(self, observation: dict) -> np.ndarray:
        return self.grasp.act(observation)[0].astype(float)


def load_policy(ref: str, spec: HandSpec, *, contract: ControlContract = ControlContract(), observation_builder=None,
                grasp_offset: np.ndarray | None = None, allow_privileged: bool = False,
                asset_root: str | None = None) -> Any:
    """``scripted``, ``close``, a checkpoint folder or ``policies/`` name, or ``package.module:factory``.

    ``contract``: what the built-in policies observe and output (a checkpoint brings its own).
    ``observation_builder``: the builder to use instead of the hardware one (the MuJoCo backend passes the
    simulator's observation, which has the privileged inputs, so no refusal applies then).
    ``grasp_offset`` (3,): palm centre → open-hand node centroid, palm frame (the scripted grasp's aim);
    computed from the hand's kinematics when None."""
    simulated = observation_builder is not None
    if ref == "close":
        policy: Any = ClosePolicy(spec, contract, close_steps=contract.episode.grasp_steps)
    elif ref == "scripted":
        from dgz_cli.runtime.observation import HardwareObservation, grasp_offset_of

        builder = observation_builder or HardwareObservation(spec, contract, asset_root=asset_root)
        offset = grasp_offset if grasp_offset is not None else grasp_offset_of(spec, asset_root)
        policy = ScriptedPolicy(spec, offset, contract, builder)
    else:
        from dgz_cli.rl.checkpoint import resolve_checkpoint

        from dgz_cli.spec.catalog import policy_ref

        checkpoint = resolve_checkpoint(policy_ref(ref))  # a shipped name resolves in a wheel install too
        if checkpoint is not None:
            from dgz_cli.runtime.trained import TrainedPolicy

            return TrainedPolicy(checkpoint, spec, ref, allow_privileged=allow_privileged or simulated,
                                 asset_root=asset_root, observation_builder=observation_builder)
        module, sep, attr = ref.partition(":")
        if not sep or not module or not attr:
            raise DgzError(f"unknown policy '{ref}'", "use 'scripted', 'close', a checkpoint folder or a name under "
                                                      "policies/ (e.g. dgz-cpu-warmstart), or package.module:factory")
        try:
            factory = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise DgzError(f"cannot load policy '{ref}': {exc}",
                           "check the module path and that it is installed") from None
        policy = factory(spec)
    if not callable(getattr(policy, "act", None)):
        raise DgzError(f"policy '{ref}' has no act(observation) method", "see docs/deploy.md (policies)")
    if not simulated:
        check_privileged(policy, ref, allow_privileged)
    return policy
