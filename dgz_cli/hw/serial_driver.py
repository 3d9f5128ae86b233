"""What every serial-bus hand driver shares: its joint mapper, bus statistics, port closing, and the two
guards on the wire:

* every joint target written to the device (policy commands, ``hold()``, the goal set in ``enable()``, the
  open pose of ``relax()``) is clipped into :meth:`command_limits` — the narrower of the spec's and the
  device's joint range, exactly the clip the runtime's safety filter applies — and rounded inward;
* every reading is checked for plausibility: a non-finite joint value, or one further than
  :data:`PLAUSIBLE_MARGIN` outside the wider of the two ranges, raises :class:`ImplausibleReading`
  naming the joint (a corrupt register, a wrong offset or a motor that lost its position), so the
  runtime stops instead of commanding from it.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.hw.driver import HandDriver
from dgz_cli.hw.errors import HardwareError, ImplausibleReading

PLAUSIBLE_MARGIN = 0.2  # rad a reading may lie outside the joint range (calibration slack, overshoot)


class SerialHandDriver(HandDriver):
    """A :class:`HandDriver` talking over one serial port (``self.ser``) through a protocol bus
    (``self.bus`` with ``stats.errors``) and mapping channels with ``self.mapper``."""

    ser = None
    bus = None
    mapper = None

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.mapper.limits()

    # -- the two guards ----------------------------------------------------------------------------
    def _spec_limits(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([j.lower for j in self.spec.joints], dtype=float),
                np.array([j.upper for j in self.spec.joints], dtype=float))

    def command_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Where a target may go: the narrower of the spec's and the device's range (the safety filter's clip)."""
        slo, shi = self._spec_limits()
        dlo, dhi = self.mapper.limits()
        lo, hi = np.maximum(slo, dlo), np.minimum(shi, dhi)
        bad = [n for n, a, b in zip(self.joint_names, lo, hi) if not a <= b]
        if bad:
            raise HardwareError(f"{self.port}: joint(s) {bad}: the spec's and the device's ranges do not overlap",
                                "check the channel offsets/signs in the hand file against the spec")
        return lo, hi

    def plausible_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Where a reading may be: the wider of the two ranges plus :data:`PLAUSIBLE_MARGIN`."""
        slo, shi = self._spec_limits()
        dlo, dhi = self.mapper.limits()
        return np.minimum(slo, dlo) - PLAUSIBLE_MARGIN, np.maximum(shi, dhi) + PLAUSIBLE_MARGIN

    def _checked(self, q: np.ndarray, native) -> np.ndarray:
        """``q`` (rad, spec order) if every joint reads a plausible value; else :class:`ImplausibleReading`."""
        q = np.asarray(q, dtype=float)
        lo, hi = self.plausible_limits()
        bad = np.flatnonzero(~np.isfinite(q) | (q < lo) | (q > hi))
        if bad.size:
            k = int(bad[0])
            raw = list(native)[int(self.mapper.perm[k])] if native is not None else "?"
            more = f" (and {bad.size - 1} more joint(s))" if bad.size > 1 else ""
            raise ImplausibleReading(
                f"{self.port}: joint '{self.joint_names[k]}' reads {q[k]:.6g} rad (raw {raw}), outside its range "
                f"[{lo[k] + PLAUSIBLE_MARGIN:.3g}, {hi[k] - PLAUSIBLE_MARGIN:.3g}] rad ± {PLAUSIBLE_MARGIN}{more}",
                "a corrupt reading, a motor that lost its position or a wrong channel offset/sign in the hand file: "
                "check the motor (vendor tool) and the hand file before moving the hand")
        return q

    def _native_targets(self, q) -> list[int]:
        """Joint targets (rad, spec order) → device units (channel order), clipped into the command limits.

        Rounding to device units never leaves the limits: a value rounded outside moves one unit inward.
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (len(self.joint_names),) or not np.all(np.isfinite(q)):
            raise HardwareError(f"{self.port}: refusing to write {q.size} joint target(s) {q.tolist()!r}: "
                                f"expected {len(self.joint_names)} finite values",
                                "this is a bug in the caller: every target must be finite")
        lo, hi = self.command_limits()
        q = np.clip(q, lo, hi)
        native = self.mapper.to_native(q)
        back = self.mapper.to_rad(native)
        eps = 1e-9
        for k in np.flatnonzero((back < lo - eps) | (back > hi + eps)):
            ch = int(self.mapper.perm[k])
            for step in (1, -1):
                trial = list(native)
                trial[ch] += step
                if self.mapper.nlo[k] <= trial[ch] <= self.mapper.nhi[k] \
                        and lo[k] - eps <= self.mapper.to_rad(trial)[k] <= hi[k] + eps:
                    native = trial
                    break
            else:
                raise HardwareError(f"{self.port}: joint '{self.joint_names[k]}': no device value lies inside "
                                    f"[{lo[k]:.4g}, {hi[k]:.4g}] rad",
                                    "the joint range is narrower than one device unit: check the hand file")
        return native

    def open_pose(self) -> np.ndarray:
        """The fully open pose (rad, spec order): each channel's native end that opens, clipped like a command."""
        opening = [c.native[0] if self.cfg.closing == "increasing" else c.native[1] for c in self.cfg.channels]
        lo, hi = self.command_limits()
        return np.clip(self.mapper.to_rad(opening), lo, hi)

    @property
    def bus_errors(self) -> int:
        return self.bus.stats.errors if self.bus else 0

    def close(self) -> None:
        if self.ser is not None:
            try:
                self.ser.close()
            except OSError:
                pass
        self.ser = None
        self.connected = False
