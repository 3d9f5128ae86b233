"""The one hand-driver interface. Joint vectors are radians in the HandSpec's ``joints`` order.

Life cycle: ``connect()`` (open, identity check; reads only) → ``enable()`` (configuration writes, torque
on; never called in a dry run) → ``read_state()`` / ``write_targets(q)`` →
``hold()`` or ``relax()`` → ``close()``. A driver is a context manager (``with driver: ...`` connects and
always closes). ``torque_off()`` is the last-resort call the runtime makes in ``finally``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from dgz_cli.spec.models import HandSpec


@dataclass
class HandState:
    q: np.ndarray                      # measured joint positions, rad, spec order
    effort: np.ndarray                 # current (mA) or force (device units), spec order
    effort_kind: str                   # "current_mA" | "force" | "sim_N·m"
    stamp: float                       # time.monotonic() when the reply arrived
    fingerprint: bytes = b""           # the raw feedback frame: identical frames in a row = frozen feedback
    native: list[int] = field(default_factory=list)  # device units, channel order


@dataclass
class DeviceInfo:
    port: str
    protocol: str
    identity: dict[str, str]

    def summary(self) -> str:
        return ", ".join(f"{k} {v}" for k, v in self.identity.items())


class HandDriver(ABC):
    protocol = "abstract"

    def __init__(self, spec: HandSpec, port: str) -> None:
        self.spec = spec
        self.port = port
        self.joint_names = [j.joint for j in spec.joints]
        self.connected = False
        self.info: DeviceInfo | None = None

    # -- interface ---------------------------------------------------------------------------------
    @abstractmethod
    def connect(self) -> DeviceInfo:
        """Open the port and check the device's identity. Reads only: safe in a dry run."""

    @abstractmethod
    def enable(self) -> None:
        """Write the configuration (modes, gains, limits) and switch the drive on. Idempotent."""

    @abstractmethod
    def read_state(self) -> HandState:
        ...

    @abstractmethod
    def write_targets(self, q: np.ndarray) -> None:
        """Command joint targets (rad, spec order); the driver clips to the device range."""

    @abstractmethod
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Device joint range (rad, spec order), known after connect."""

    def hold(self) -> None:
        """Keep the current position (targets := measured)."""
        self.write_targets(self.read_state().q)

    @abstractmethod
    def relax(self) -> None:
        """Let go: torque off (backdrivable servos) or open slowly (self-locking linear actuators)."""

    @abstractmethod
    def torque_off(self) -> None:
        """Remove drive power where the device allows it; see each driver for what that means."""

    @abstractmethod
    def close(self) -> None:
        """Release the port (no motion)."""

    @property
    def bus_errors(self) -> int:
        return 0

    # -- context manager ---------------------------------------------------------------------------
    def __enter__(self) -> "HandDriver":
        if not self.connected:
            self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()
