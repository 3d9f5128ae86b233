"""What the control loop exchanges with policies and observation builders (no imports of other runtime
modules, so every runtime module can use it without cycles)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dgz_cli.hw.driver import HandState
from dgz_cli.spec.contract import PRIVILEGED_BLOCKS
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec


@runtime_checkable
class Policy(Protocol):
    """``act(observation) -> (action_dim,)`` normalized actions in the control contract's layout (6 wrist +
    3 per node, one unit = the contract's scale, clipped to [-1, 1] by the loop). Optional: ``reset()``,
    ``privileged_inputs`` (names of observation blocks a real hand cannot provide), ``observation_builder``,
    ``contract`` (the :class:`~dgz_cli.spec.contract.ControlContract` it was trained with)."""

    def act(self, observation: Any) -> np.ndarray: ...


@dataclass
class StepInput:
    """What an observation builder may use at control step k."""

    k: int
    state: HandState | None      # None when this step's read failed (transient bus error)
    target: np.ndarray           # current joint targets (rad, spec order)
    last_action: np.ndarray      # the previous normalized action, clipped to [-1, 1]
    wrist_command: np.ndarray    # the previous wrist command sent to the arm (m, rad; palm frame)
    palm_pose: tuple[np.ndarray, np.ndarray] | None = None  # commanded palm pose in the start palm frame


class ObservationBuilder(Protocol):
    def reset(self, spec: HandSpec, context: dict) -> None: ...

    def build(self, step: StepInput) -> Any: ...


def privileged_needs(policy: Any) -> list[str]:
    """The privileged inputs (sorted) a policy observes that a real hand cannot provide."""
    return sorted(PRIVILEGED_BLOCKS & set(getattr(policy, "privileged_inputs", ()) or ()))


def check_privileged(policy: Any, name: str, allow_privileged: bool = False) -> None:
    needs = privileged_needs(policy)
    if needs and not allow_privileged:
        raise DgzError(f"policy '{name}' needs privileged inputs ({', '.join(needs)}) that a real hand "
                       "does not provide",
                       "deploy a student policy distilled without contact/force inputs (paper Supp. S2), or "
                       "pass --allow-privileged to feed zeros instead (for tests; the policy may misbehave)")
