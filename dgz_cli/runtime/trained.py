"""A trained MAGCN checkpoint as a deploy policy.

``--policy`` takes a checkpoint folder (``model.safetensors`` + ``checkpoint.yaml``, written by
``dgz train``) or the name of a folder under ``policies/``, resolved as ``dgz eval --policy`` does. Weights
load without pickle (:func:`dgz_cli.rl.runner.load_policy`); torch is imported only here.

Privileged inputs: the checkpoint's metadata key ``privileged_inputs`` lists the observations the policy
was trained with that a real hand lacks (``contact``, ``force``). A checkpoint *without* the key is treated
as privileged (``["contact", "force"]``): every teacher trained by ``dgz train`` observes both. Such a
policy is refused unless explicitly allowed; then those inputs are fed as zeros.

The policy acts deterministically (the Gaussian's mean); outputs are normalized actions in [-1, 1] that the
runtime scales (0.01 wrist, 0.015 fingers), clips and maps through M_h.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dgz_cli.runtime.observation import HardwareObservation
from dgz_cli.runtime.policy import check_privileged
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec

ASSUMED_PRIVILEGED = ("contact", "force")
KNOWN_INPUTS = frozenset({"contact", "force"})


def privileged_inputs(meta: dict, where: Path) -> frozenset[str]:
    value = meta.get("privileged_inputs", list(ASSUMED_PRIVILEGED))
    if not isinstance(value, list) or not all(isinstance(v, str) and v in KNOWN_INPUTS for v in value):
        raise DgzError(f"{where / 'checkpoint.yaml'}: field 'privileged_inputs' must be a list drawn from "
                       f"{sorted(KNOWN_INPUTS)}, got {value!r}", "fix the checkpoint metadata")
    return frozenset(value)


class TrainedPolicy:
    normalized_actions = True

    def __init__(self, directory: Path, spec: HandSpec, name: str, allow_privileged: bool = False,
                 asset_root: str | None = None) -> None:
        import torch

        from dgz_cli.rl.runner import load_policy
        from dgz_cli.sim.config import EnvConfig
        from dgz_cli.sim.observe import GLOBAL_DIM, NODE_DIM

        self.name, self.directory = name, Path(directory)
        self.model, self.meta = load_policy(self.directory)
        self.privileged_inputs = privileged_inputs(self.meta, self.directory)
        check_privileged(self, name, allow_privileged)  # before anything that needs the hand's URDF
        where = self.directory / "checkpoint.yaml"
        mode = self.meta["policy"].get("action_mode", "primitive")
        if mode != "primitive":
            raise DgzError(f"{where}: action_mode '{mode}' cannot be deployed",
                           "the runtime maps per-node primitive actions through M_h: deploy a 'primitive' policy")
        cfg = self.model.cfg
        if (cfg.node_dim, cfg.global_dim) != (NODE_DIM, GLOBAL_DIM):
            raise DgzError(f"{where}: the model expects {cfg.node_dim}/{cfg.global_dim} node/global features, "
                           f"this dgz builds {NODE_DIM}/{GLOBAL_DIM}", "use a checkpoint from this dgz version")
        env = {k: v for k, v in (self.meta.get("env") or {}).items() if k in EnvConfig.model_fields}
        env_cfg = EnvConfig.model_validate(env)
        self.observation_builder = HardwareObservation(spec, env_cfg.distance_clip, env_cfg.force_scale, asset_root)
        self.action_dim = 6 + 3 * len(spec.nodes)
        self._torch = torch
        torch.set_num_threads(1)  # batch-1 inference; leave the cores to the bus and the loop

    def reset(self) -> None:
        pass

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """Observation (see :class:`HardwareObservation`) → mean action (6 + 3N,) in normalized units."""
        from dgz_cli.policy.graph import to_tensors

        with self._torch.no_grad():
            mean = self.model(to_tensors(observation))[0]
        return mean[0].numpy().astype(float)
