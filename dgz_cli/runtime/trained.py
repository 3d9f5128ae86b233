"""A trained MAGCN checkpoint as a deploy policy.

``--policy`` takes a checkpoint folder (written by ``dgz train``) or the name of a folder under
``policies/``, resolved as ``dgz eval --policy`` does, and loaded by the same loader
(:class:`dgz_cli.rl.checkpoint.LoadedPolicy`: no pickle, weights hash checked). The control contract the
policy was trained with comes from the checkpoint: it lays out the observation, scales the actions and
sets the rate and the episode phases of the run.

Privileged inputs: observation blocks a real hand lacks (``contact``, ``force``; the contract lists those
its layout holds). Such a policy is refused on hardware unless explicitly allowed; then those inputs are
fed as zeros. On the MuJoCo backend the simulator provides them.

The policy acts deterministically (the Gaussian's mean). A distilled student (``dgz distill``, checkpoint
format 3) has no privileged input and keeps a history of its last steps; :meth:`TrainedPolicy.reset`, which
the control loop calls before the episode, clears it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dgz_cli.runtime.types import check_privileged
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec


class TrainedPolicy:
    def __init__(self, directory: Path, spec: HandSpec, name: str, allow_privileged: bool = False,
                 asset_root: str | None = None, observation_builder=None) -> None:
        from dgz_cli.rl.checkpoint import LoadedPolicy

        self.name, self.directory = name, Path(directory)
        self.loaded = LoadedPolicy(self.directory)
        self.meta, self.contract = self.loaded.meta, self.loaded.meta.contract
        self.privileged_inputs = frozenset(self.contract.privileged_inputs)
        check_privileged(self, name, allow_privileged)  # before anything that needs the hand's URDF
        if observation_builder is None:
            from dgz_cli.runtime.observation import HardwareObservation

            observation_builder = HardwareObservation(spec, self.contract, asset_root)
        self.observation_builder = observation_builder
        self.action_dim = self.contract.action.dim(len(spec.nodes))
        if self.contract.action.mode != "primitive":
            lengths = {}
            for row in spec.joints:
                lengths[row.node] = lengths.get(row.node, 0) + 1
            if max(lengths.values(), default=0) > self.contract.action.n_prim:
                raise DgzError(f"{self.directory}: a joint-mode policy drives ≤ {self.contract.action.n_prim} joints "
                               f"per node; {spec.name} has a node with {max(lengths.values())}",
                               "use a primitive-mode policy for this hand")

    def reset(self) -> None:
        self.loaded.reset()

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """Observation (the contract's layout, batch of 1) → mean action (action_dim,), normalized."""
        return self.loaded.act(observation)[0].astype(float)
