"""The arm interface that executes the wrist command, and the pose math shared by every arm.

A wrist command is 6 numbers per control step: Δp (m) and Δθ (rad, rotation vector), in the *palm frame*
(axes f, l, n of the HandSpec) or the arm's *base frame*, plus the protocol's ``lift`` (m along the base
+z, not subject to the per-step cap, as in the simulator).
:class:`WristTracker` integrates such increments into a flange target in the base frame, with a per-step
cap, a workspace box and a maximum rotation away from the start orientation, and reports the palm pose
relative to the palm frame at the start (what the observation builder needs).

Arms (``--arm``): ``none`` logs the command and never moves (the palm stays where it is), ``sim`` is an
ideal arm (the target is reached at once; palm facing down at the start, as in the training scenes),
``piper`` drives an AgileX Piper (:mod:`dgz_cli.hw.piper`). Life cycle: ``connect()`` (reads only) →
``enable()`` → ``command()`` per step → ``hold()`` at exit → ``close()``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NOMINAL_PALM = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # palm down (= sim.scene)


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """(3,) rotation vector → (3, 3) rotation matrix (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def matrix_angle(r: np.ndarray) -> float:
    """Rotation angle (rad) of a (3, 3) rotation matrix."""
    return float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))


def euler_to_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """Fixed-axis X, then Y, then Z (rad): R = Rz · Ry · Rx."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rx_m = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry_m = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz_m = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz_m @ ry_m @ rx_m


def matrix_to_euler(r: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix` → (3,) rad (rx, ry, rz), ry in [-π/2, π/2]."""
    ry = np.arcsin(np.clip(-r[2, 0], -1.0, 1.0))
    if abs(np.cos(ry)) < 1e-9:  # gimbal lock: put everything into rz
        return np.array([0.0, ry, np.arctan2(-r[0, 1], r[1, 1])])
    return np.array([np.arctan2(r[2, 1], r[2, 2]), ry, np.arctan2(r[1, 0], r[0, 0])])


@dataclass(frozen=True)
class ArmLimits:
    workspace: np.ndarray          # (3, 2) [min, max] per base axis, m
    max_step_m: float = 0.01
    max_step_rad: float = 0.02
    max_rotation: float = np.pi / 4  # rad from the start orientation


class WristTracker:
    """Integrates wrist increments into a flange target (base frame) under :class:`ArmLimits`.

    ``r_fp`` (3, 3): palm axes (columns f, l, n) in the flange frame; ``c_fp`` (3,): palm centre in the
    flange frame. Rotations turn about the flange origin (as the training env's wrist hinges do).
    """

    def __init__(self, r_fp: np.ndarray, c_fp: np.ndarray, limits: ArmLimits) -> None:
        self.r_fp, self.c_fp, self.limits = np.asarray(r_fp, float), np.asarray(c_fp, float), limits
        self.start(np.zeros(3), np.eye(3))

    def start(self, p_flange: np.ndarray, r_flange: np.ndarray) -> None:
        self.p, self.r = np.asarray(p_flange, float).copy(), np.asarray(r_flange, float).copy()
        self.p0, self.r0 = self.p.copy(), self.r.copy()
        self.palm0 = self._palm(self.p, self.r)

    def _palm(self, p: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return p + r @ self.c_fp, r @ self.r_fp

    def step(self, delta: np.ndarray, frame: str = "palm", lift: float = 0.0) -> bool:
        """Apply one increment (6,) and a lift (m, base +z); returns True when a limit changed it."""
        d = np.asarray(delta, dtype=float).reshape(6)
        to_base = self.r @ self.r_fp if frame == "palm" else np.eye(3)
        dp, dw = to_base @ d[:3], to_base @ d[3:]
        lim = self.limits
        limited = False
        for v, cap in ((dp, lim.max_step_m), (dw, lim.max_step_rad)):
            n = float(np.linalg.norm(v))
            if n > cap:
                v *= cap / n
                limited = True
        dp = dp + np.array([0.0, 0.0, float(lift)])
        p = np.clip(self.p + dp, lim.workspace[:, 0], lim.workspace[:, 1])
        r = rotvec_to_matrix(dw) @ self.r
        if matrix_angle(r @ self.r0.T) > lim.max_rotation:
            r, limited = self.r, True  # refuse rotations beyond the cone, keep the translation
        limited |= bool(np.any(p != self.p + dp))
        self.p, self.r = p, r
        return limited

    def palm_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Commanded palm pose in the start palm frame: position (3,) m, rotation (3, 3)."""
        p, r = self._palm(self.p, self.r)
        p0, r0 = self.palm0
        return r0.T @ (p - p0), r0.T @ r


class ArmInterface:
    """``none``: logs the wrist command, never moves; the palm stays at the start pose."""

    name = "none"
    moves = False

    def connect(self) -> str:
        return "no arm: wrist commands are logged only"

    def enable(self) -> None:
        pass

    def command(self, delta: np.ndarray, frame: str = "palm", lift: float = 0.0) -> dict:
        return {}

    def palm_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(3), np.eye(3)

    def hold(self) -> str:
        return "none"

    def close(self) -> None:
        pass


class SimArm(ArmInterface):
    """An ideal arm: every target is reached at once. The base frame is the training scenes' world: the palm
    faces down (−z) at the start, fingers along +x, the flange at the origin; the lift goes along +z."""

    name = "sim"
    moves = True

    def __init__(self, r_fp: np.ndarray, c_fp: np.ndarray, limits: ArmLimits | None = None) -> None:
        box = np.array([[-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5]])
        self.tracker = WristTracker(r_fp, c_fp, limits or ArmLimits(box))

    def connect(self) -> str:
        return "ideal simulated arm"

    def enable(self) -> None:
        self.tracker.start(np.zeros(3), NOMINAL_PALM @ self.tracker.r_fp.T)

    def command(self, delta: np.ndarray, frame: str = "palm", lift: float = 0.0) -> dict:
        limited = self.tracker.step(delta, frame, lift)
        return {"arm_target": [*self.tracker.p, *matrix_to_euler(self.tracker.r)], "arm_limited": limited}

    def palm_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.tracker.palm_pose()

    def hold(self) -> str:
        return "hold"
