"""The pose ``dgz deploy`` ramps the hand to before the policy's first step: the control contract's start pose
(:class:`dgz_cli.spec.contract.StartPose`, the pose every simulated episode of the policy started from: the
flat open hand, or the thumb pre-opened as in the paper's Supp. S2), then the hand file's ``start_pose``
entries. The runtime clips the result to the narrower of spec and device limits before ramping to it."""

from __future__ import annotations

import numpy as np

from dgz_cli.runtime.mapping import start_pose
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.models import HandSpec


def deploy_start_pose(spec: HandSpec, contract: ControlContract,
                      overrides: dict[str, float] | None = None) -> np.ndarray:
    """(L,) the contract's start pose for ``spec``, then ``overrides`` (joint → rad), clipped into the limits."""
    return start_pose(spec, overrides, base=contract.start.pose(spec))
