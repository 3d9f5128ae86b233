"""The policy interface the runtime drives, a scripted policy, and pluggable observation builders.

A policy is any object with ``act(observation) -> np.ndarray`` of ``6 + 3·N_nodes`` numbers (see
:mod:`dgz_cli.runtime.mapping`), optionally ``reset()``, ``privileged_inputs`` (a set of names; policies
that need "contact" or "force" are refused on hardware unless explicitly allowed) and ``normalized_actions``
(True when outputs are in [-1, 1] and must be multiplied by the action scales 0.01 wrist / 0.015 fingers).
Load one by name (``scripted``), as a trained checkpoint (a folder, or a name under ``policies/``; see
:mod:`dgz_cli.runtime.trained`) or by reference ``package.module:factory`` (called with the HandSpec). A
policy that needs its own observations carries an ``observation_builder`` attribute (used instead of the
default).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dgz_cli.hw.driver import HandState
from dgz_cli.runtime.mapping import WRIST_DIM, MhMap
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec

PRIVILEGED = frozenset({"contact", "force"})


@runtime_checkable
class Policy(Protocol):
    def act(self, observation: Any) -> np.ndarray: ...


@dataclass
class StepInput:
    """What an observation builder may use at step k."""

    k: int
    state: HandState | None      # None when this step's read failed (transient bus error)
    target: np.ndarray           # current joint targets (rad, spec order)
    last_action: np.ndarray      # the previous clipped action
    wrist_command: np.ndarray    # the previous filtered wrist command
    palm_pose: tuple[np.ndarray, np.ndarray] | None = None  # commanded palm pose in the start palm frame


class ObservationBuilder(Protocol):
    def reset(self, spec: HandSpec, context: dict) -> None: ...

    def build(self, step: StepInput) -> Any: ...


class ProprioObservation:
    """Default builder: a dict of proprioception plus the grasp target point (object centroid, palm frame at
    the start) if known.

    Trained policies bring their own builder (same two methods) that assembles exactly the tensors the
    network was trained on.
    """

    def reset(self, spec: HandSpec, context: dict) -> None:
        self.spec = spec
        pts = context.get("object_points")
        self.object_point = None if pts is None else np.asarray(pts, dtype=float).reshape(-1, 3).mean(axis=0)

    def build(self, step: StepInput) -> dict:
        s = step.state
        return {"step": step.k, "q": None if s is None else s.q, "effort": None if s is None else s.effort,
                "target": step.target, "last_action": step.last_action, "wrist_command": step.wrist_command,
                "object_point": self.object_point}


class ScriptedClosePolicy:
    """Zero wrist command and +FLEX on every node at a constant rate for ``close_steps``, then hold (zeros)."""

    name = "scripted"
    privileged_inputs = frozenset()
    normalized_actions = False

    def __init__(self, spec: HandSpec, rate: float = 0.01, close_steps: int = 130) -> None:
        self.mh = MhMap(spec)
        self.rate = rate
        self.close_steps = close_steps
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def act(self, observation: Any) -> np.ndarray:
        a = np.zeros(self.mh.action_dim)
        if self.k < self.close_steps:
            a[WRIST_DIM::3] = self.rate  # FLEX column of every node
        self.k += 1
        return a


def privileged_needs(policy: Any) -> list[str]:
    """The privileged inputs (sorted) a policy observes that a real hand cannot provide."""
    return sorted(PRIVILEGED & set(getattr(policy, "privileged_inputs", ()) or ()))


def check_privileged(policy: Any, name: str, allow_privileged: bool = False) -> None:
    needs = privileged_needs(policy)
    if needs and not allow_privileged:
        raise DgzError(f"policy '{name}' needs privileged inputs ({', '.join(needs)}) that a real hand "
                       "does not provide",
                       "deploy a student policy distilled without contact/force inputs (paper Supp. S2), or "
                       "pass --allow-privileged to feed zeros instead (for tests; the policy may misbehave)")


def load_policy(ref: str, spec: HandSpec, allow_privileged: bool = False, asset_root: str | None = None) -> Any:
    """``scripted``, a checkpoint folder or ``policies/`` name, or ``package.module:factory``."""
    from dgz_cli.rl.checkpoint import resolve_checkpoint
    from dgz_cli.runtime.trained import TrainedPolicy

    checkpoint = None if ref == "scripted" else resolve_checkpoint(ref)
    if ref == "scripted":
        policy: Any = ScriptedClosePolicy(spec)
    elif checkpoint is not None:
        policy = TrainedPolicy(checkpoint, spec, ref, allow_privileged=allow_privileged, asset_root=asset_root)
    else:
        module, sep, attr = ref.partition(":")
        if not sep or not module or not attr:
            raise DgzError(f"unknown policy '{ref}'", "use 'scripted', a checkpoint folder or a name under "
                                                      "policies/ (e.g. dgz-cpu-first), or package.module:factory")
        try:
            factory = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise DgzError(f"cannot load policy '{ref}': {exc}",
                           "check the module path and that it is installed") from None
        policy = factory(spec)
    if not callable(getattr(policy, "act", None)):
        raise DgzError(f"policy '{ref}' has no act(observation) method", "see docs/deploy.md (policies)")
    check_privileged(policy, ref, allow_privileged)
    return policy
