"""Kalman filter for the wrist command: a constant-velocity model per axis (paper: "apply a Kalman filter
to the control signals to reduce jitter").

State per axis x = [c, ċ]; F = [[1, dt], [0, 1]]; H = [1, 0]; process noise from a white acceleration of
variance q: Q = q·[[dt⁴/4, dt³/2], [dt³/2, dt²]]; measurement variance r. The state starts at zero (no
motion) with covariance p0·I. ``update(z)`` predicts, then corrects, and returns the filtered c.
"""

from __future__ import annotations

import numpy as np


class KalmanCV:
    def __init__(self, dim: int = 6, dt: float = 0.05, q: float = 2.5e-3, r: float = 9e-6, p0: float = 1e-4) -> None:
        self.dim, self.dt, self.q, self.r, self.p0 = dim, dt, q, r, p0
        self.F = np.array([[1.0, dt], [0.0, 1.0]])
        self.Q = q * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros((self.dim, 2))
        self.P = np.repeat((self.p0 * np.eye(2))[None], self.dim, axis=0)

    def update(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=float).reshape(self.dim)
        F = self.F
        self.x = self.x @ F.T                                   # predict
        self.P = F @ self.P @ F.T + self.Q
        S = self.P[:, 0, 0] + self.r                             # correct (H = [1, 0])
        K = self.P[:, :, 0] / S[:, None]                         # (dim, 2)
        innovation = z - self.x[:, 0]
        self.x = self.x + K * innovation[:, None]
        KH = np.zeros((self.dim, 2, 2))
        KH[:, :, 0] = K
        self.P = (np.eye(2)[None] - KH) @ self.P
        return self.x[:, 0].copy()

    @property
    def velocity(self) -> np.ndarray:
        return self.x[:, 1].copy()
