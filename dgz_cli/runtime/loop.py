"""The control loop: read → observe → policy → safety → write at a fixed rate, with a safe exit.

Phases: ``ramp`` (slowly to the start pose, skipped in a dry run), then the control contract's episode
(:class:`~dgz_cli.spec.contract.EpisodeProtocol`, the one ``dgz eval`` runs): ``grasp``, ``lift`` and
``hold`` steps at the contract's rate, the policy acting at every step, its actions clipped and scaled
by the contract; during ``lift`` the arm also rises by ``lift_height / lift_steps`` per step along its
base +z. The wrist command (palm frame) goes to the arm interface each step, Kalman-filtered on real arms
(``wrist_filter``); ``none`` only logs it.
Faults stop the loop at once: a device or arm fault or disconnect, a non-finite action, ``max_bus_errors``
lost/garbled replies in a row, ``stale_reads`` repeated feedback frames while the hand is being moved,
``max_overruns`` late steps in a row, or a policy exception. At exit the arm holds first, then the hand
takes ``on_exit`` (hold or relax; a second Ctrl-C relaxes at once); if that fails, ``torque_off()`` runs
in ``finally``. SIGTERM and SIGHUP are handled like Ctrl-C (exit code 143 instead of 130). A dry run reads
but never writes (hand or arm).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from dgz_cli.hw.arm import ArmInterface
from dgz_cli.hw.driver import HandDriver
from dgz_cli.hw.errors import TRANSIENT, HardwareError, StaleFeedback
from dgz_cli.runtime.filters import KalmanCV
from dgz_cli.runtime.policy import ProprioObservation
from dgz_cli.runtime.rate import InterruptGuard, RateLoop
from dgz_cli.runtime.safety import SafetyConfig, SafetyFilter
from dgz_cli.runtime.steplog import StepLogger
from dgz_cli.runtime.types import StepInput
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec


class LoopOverrun(DgzError):
    """The loop missed its deadline too many times in a row."""


class _StopRequested(Exception):
    pass


@dataclass
class RunConfig:
    contract: ControlContract = field(default_factory=ControlContract)  # rate, phases, scales: the policy's
    on_exit: str = "hold"
    wrist_filter: bool = True  # Kalman-smooth the wrist command for a real arm (off on the MuJoCo backend)
    dry_run: bool = False
    max_bus_errors: int = 3
    stale_reads: int = 3
    max_overruns: int = 5
    ramp_speed: float = 0.3  # rad/s
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    max_tracking_error: float = 1.0  # rad: |target − measured| above this ...
    tracking_steps: int = 10  # ... for this many reads in a row while moving is a fault
    min_travel: float = 0.05  # rad: ... on a joint that has not moved this far since the episode began


@dataclass
class RunResult:
    ok: bool = False
    exit_code: int = 1
    reason: str = ""
    hint: str = ""
    steps: int = 0
    ramp_steps: int = 0
    overruns: int = 0
    bus_errors: int = 0
    exit_action: str = "none"
    arm_exit: str = "none"
    target: np.ndarray | None = None
    measured: np.ndarray | None = None
    periods: list = field(default_factory=list)


class Runner:
    def __init__(self, driver: HandDriver, spec: HandSpec, policy, cfg: RunConfig | None = None, builder=None,
                 logger: StepLogger | None = None, guard: InterruptGuard | None = None, context: dict | None = None,
                 clock=time.monotonic, sleep=time.sleep, arm: ArmInterface | None = None,
                 grasp_offset: np.ndarray | None = None) -> None:
        """``grasp_offset`` (3,): palm centre → open-hand node centroid, palm frame (the wrist guidance's
        guided point; needed only when the contract's guidance is on)."""
        cfg = cfg or RunConfig()
        if cfg.on_exit not in ("hold", "relax"):
            raise DgzError(f"--on-exit {cfg.on_exit!r} is not supported", "use hold or relax")
        self.driver, self.spec, self.policy, self.cfg = driver, spec, policy, cfg
        self.builder = builder or getattr(policy, "observation_builder", None) or ProprioObservation()
        self.log = logger or StepLogger(None)
        self.guard = guard or InterruptGuard()
        self.rate_hz = cfg.contract.episode.control_hz
        self.context = {"rate_hz": self.rate_hz, **(context or {})}
        self.arm = arm or ArmInterface()
        self.clock, self.sleep = clock, sleep
        self.grasp_offset = None if grasp_offset is None else np.asarray(grasp_offset, dtype=float)
        self.action_dim = cfg.contract.action.dim(len(spec.nodes))
        self.kf = KalmanCV(cfg.contract.action.wrist_dim, 1.0 / self.rate_hz)
        self.res = RunResult()
        self._streak = self._stale = 0
        self._q_first: np.ndarray | None = None  # the first finite reading (of the run, then of the episode)
        self._prev_fp = self._prev_written = None
        self._moving = False

    # -- bus helpers -------------------------------------------------------------------------------
    def _transient(self, exc: HardwareError) -> None:
        self.res.bus_errors += 1
        self._streak += 1
        if self._streak >= self.cfg.max_bus_errors:
            raise HardwareError(f"{self._streak} bus errors in a row; last: {exc.message}", exc.hint)

    def _read(self, required: bool = False):
        while True:
            try:
                state = self.driver.read_state()
            except TRANSIENT as exc:
                self._transient(exc)
                if required:
                    continue
                return None
            self._streak = 0
            self._check_stale(state)
            self._check_feedback(state)
            self.res.measured = state.q
            return state

    def _write(self, target: np.ndarray) -> None:
        if self.cfg.dry_run:
            return
        self._moving = self._prev_written is not None and bool(np.any(np.abs(target - self._prev_written) > 1e-9))
        self._prev_written = target.copy()
        try:
            self.driver.write_targets(target)
        except TRANSIENT as exc:
            self._transient(exc)

    def _check_feedback(self, state) -> None:
        """A non-finite reading, or a joint that does not follow its target (|target − measured| above
        ``max_tracking_error`` for ``tracking_steps`` reads in a row while moving, on a joint that has not moved
        ``min_travel`` since the episode's first reading), stops the run naming the joint. A finger that closed and is then
        held by the object leads its target by as much as the contract lets it: that is the grasp, not a fault."""
        q = np.asarray(state.q, dtype=float).reshape(-1)
        names = [r.joint for r in self.spec.joints]
        bad = np.flatnonzero(~np.isfinite(q))
        if bad.size:
            i = int(bad[0])
            raise HardwareError(f"{self.driver.port}: joint '{names[i] if i < len(names) else i}' reads {q[i]} "
                                "(not a finite position)", "check the hand's wiring and firmware; the reading "
                                "came from the device, not from the policy")
        if self._q_first is None or self._q_first.shape != q.shape:
            self._q_first = q.copy()
        if self.cfg.dry_run or self._prev_written is None or not self._moving or q.shape != self._prev_written.shape:
            self._tracking = 0
            return
        err = np.abs(self._prev_written - q)
        err[np.abs(q - self._q_first) > self.cfg.min_travel] = 0.0
        self._tracking = getattr(self, "_tracking", 0) + 1 if float(err.max()) > self.cfg.max_tracking_error else 0
        if self._tracking >= self.cfg.tracking_steps:
            i = int(np.argmax(err))
            raise HardwareError(f"{self.driver.port}: joint '{names[i]}' does not follow its target: "
                                f"|target − measured| = {err[i]:.3f} rad > {self.cfg.max_tracking_error:g} rad for "
                                f"{self._tracking} reads in a row", "check that the joint is not blocked or "
                                "unpowered (torque on, supply voltage) and that the hand file's offsets are right")

    def _check_stale(self, state) -> None:
        if self.cfg.dry_run or not state.fingerprint:
            return
        if state.fingerprint == self._prev_fp and self._moving:
            self._stale += 1
            if self._stale >= self.cfg.stale_reads:
                raise StaleFeedback(f"{self.driver.port}: feedback frozen: {self._stale} reads in a row repeated the "
                                    "previous frame while the hand was commanded to move",
                                    "the hand's controller may have hung: power-cycle it and check the cable")
        else:
            self._stale = 0
        self._prev_fp = state.fingerprint

    # -- phases ------------------------------------------------------------------------------------
    def _tick(self, k: int, phase: str, t_start: float, **fields) -> None:
        late = self.rate.wait()
        self.log.step(k=k, phase=phase, t=t_start - self.rate.t0, loop_ms=1e3 * (self.clock() - t_start),
                      late_ms=1e3 * max(late, 0.0), overrun=late > 0, bus_errors=self.res.bus_errors, **fields)
        if self.rate.consecutive >= self.cfg.max_overruns:
            raise LoopOverrun(f"control loop late {self.rate.consecutive} steps in a row "
                              f"({1e3 * self.rate.period:.0f} ms period, last {1e3 * late:.1f} ms late)",
                              "the policy or the bus is too slow for this rate: use a faster machine/GPU, "
                              "close other programs, or lower the rate")

    def _ramp(self, start_pose: np.ndarray) -> None:
        safety, step = self.safety, self.cfg.ramp_speed / self.rate_hz
        goal = np.clip(start_pose, safety.lo, safety.hi)
        n_max = int(np.ceil(np.max(np.abs(goal - safety.target)) / step)) + 1
        for k in range(n_max):
            if self.guard.stop_requested:
                raise _StopRequested
            t0 = self.clock()
            target = safety.approach(goal, step)
            self._write(target)
            state = self._read()
            self.res.ramp_steps += 1
            self._tick(k, "ramp", t0, target=target, measured=None if state is None else state.q)
            if np.max(np.abs(goal - target)) < 1e-12:
                break

    def _episode(self) -> None:
        cfg, safety, ep = self.cfg, self.safety, self.cfg.contract.episode
        last_action = np.zeros(self.action_dim)
        wrist = np.zeros(cfg.contract.action.wrist_dim)
        self._q_first = None  # travel counts from the start pose: a joint the ramp moved may still jam
        for k in range(ep.episode_steps):
            if self.guard.stop_requested:
                raise _StopRequested
            t0 = self.clock()
            phase = ep.phase(k)
            state = self._read()
            obs = self.builder.build(StepInput(k, state, safety.target.copy(), last_action, wrist, self.arm.palm_pose()))
            raw = np.asarray(self.policy.act(obs), dtype=float).reshape(-1)
            cmd = safety.step(self._compose(raw, obs), q=None if state is None else state.q)
            command = self._wrist_command(cmd, obs, phase)
            wrist = self.kf.update(command) if cfg.wrist_filter else command
            lift = ep.lift_per_step() if phase == "lift" else 0.0
            arm_log = {} if cfg.dry_run else self.arm.command(wrist, "palm", lift=lift)
            self._write(cmd.target)
            last_action = cmd.action
            self.res.steps += 1
            self.res.target = cmd.target
            self._tick(k, phase, t0, action=raw, wrist_cmd=cmd.wrist, wrist_sent=wrist, lift=lift, arm=self.arm.name,
                       target=cmd.target, measured=None if state is None else state.q,
                       effort=None if state is None else state.effort, limited=cmd.limited, **arm_log)

    def _compose(self, raw: np.ndarray, obs) -> np.ndarray:
        """The command before the safety filter: the policy's action scaled by the contract's residual gains
        plus its closing prior, from the observation — the simulator's computation (``ControlContract.compose``)."""
        c = self.cfg.contract
        if not c.prior.enabled and not c.action.scales_residual:
            return raw
        obs_arrays = [np.asarray(obs[k]) for k in ("nodes", "global", "closing", "node_valid")]
        return c.compose(raw[None], *obs_arrays)[0]

    def _wrist_command(self, cmd, obs, phase: str) -> np.ndarray:
        """The wrist command (6,) m and rad: the safe command's wrist plus the contract's wrist guidance (none
        when off) from the observation's target block — the simulator's computation
        (``ControlContract.wrist_command``)."""
        c = self.cfg.contract
        if c.guidance.gain == 0.0:
            return cmd.wrist
        if self.grasp_offset is None or not isinstance(obs, dict) or "global" not in obs:
            raise DgzError("the policy's contract guides the wrist, but its observation has no grasp target",
                           "give the policy its own observation builder (trained checkpoints bring one)")
        if c.guidance.stop_gap is not None and not {"nodes", "node_valid"} <= obs.keys():
            raise DgzError("the policy's contract stops the wrist guidance near the object, but its observation has "
                           "no palm → surface distance (nodes)",
                           "give the policy its own observation builder (trained checkpoints bring one)")
        return c.wrist_command(cmd.action[None, :c.action.wrist_dim], obs["global"], self.grasp_offset[None],
                               np.array([phase == "grasp"]), obs.get("nodes"), obs.get("node_valid"))[0]

    # -- entry point -------------------------------------------------------------------------------
    def run(self, start_pose: np.ndarray | None = None) -> RunResult:
        res, cfg = self.res, self.cfg
        immediate = False
        try:
            self.safety = SafetyFilter(self.spec, self.driver.limits(), cfg.contract, cfg.safety)
            first = self._read(required=True)
            self.safety.reset(first.q)
            self.builder.reset(self.spec, self.context)
            if hasattr(self.policy, "reset"):
                self.policy.reset()
            if not cfg.dry_run:
                self.driver.enable()
                self.arm.enable()
            self.rate = RateLoop(self.rate_hz, self.clock, self.sleep)  # after enabling: that may take a while
            if not cfg.dry_run and start_pose is not None:
                self._ramp(np.asarray(start_pose, dtype=float))
            self._episode()
            res.ok, res.exit_code = True, 0
            ep = cfg.contract.episode
            res.reason = (f"completed {res.steps} steps ({ep.grasp_steps} grasp + {ep.lift_steps} lift + "
                          f"{ep.hold_steps} hold)")
        except _StopRequested:
            res.exit_code, what = self._stopped_by()
            res.reason = f"stopped by {what} after {res.steps} steps"
        except KeyboardInterrupt:
            immediate = True
            res.exit_code, _ = self._stopped_by()
            res.reason = f"{getattr(self.guard, 'second', 'second Ctrl-C')}: relaxing at once"
        except DgzError as exc:
            res.reason, res.hint = exc.message, exc.hint
        except Exception as exc:  # a policy or observation builder bug must still end in a safe stop
            res.reason = f"{type(exc).__name__} in the control loop: {' '.join(str(exc).split())}"
            res.hint = "this is a bug in the policy or observation builder; the hand was stopped"
        finally:
            if not cfg.dry_run:
                res.arm_exit = self._arm_exit()
                res.exit_action = self._safe_exit(immediate)
            rate = getattr(self, "rate", None)
            if rate is not None:
                res.overruns, res.periods = rate.overruns, list(rate.periods)
            self.log.end(ok=res.ok, exit_code=res.exit_code, reason=res.reason, hint=res.hint, steps=res.steps,
                         overruns=res.overruns, bus_errors=res.bus_errors, exit_action=res.exit_action,
                         arm_exit=res.arm_exit)
        return res

    def _stopped_by(self) -> tuple[int, str]:
        """(exit code, what stopped the run): 130 for Ctrl-C, 143 for SIGTERM or SIGHUP (see docs/deploy.md)."""
        return getattr(self.guard, "exit_code", 130), getattr(self.guard, "what", "Ctrl-C")

    def _arm_exit(self) -> str:
        """Stop the arm where it is (first, so the hand is not carried on while it lets go)."""
        try:
            return self.arm.hold()
        except (Exception, KeyboardInterrupt) as exc:
            return f"failed: {' '.join(str(getattr(exc, 'message', exc)).split())}"

    def _safe_exit(self, immediate: bool) -> str:
        want = "relax" if immediate or self.cfg.on_exit == "relax" else "hold"
        try:
            (self.driver.relax if want == "relax" else self.driver.hold)()
            return want
        except (Exception, KeyboardInterrupt):
            pass
        try:
            self.driver.torque_off()
            return "torque off"
        except (Exception, KeyboardInterrupt):
            return "none (hand unreachable)"
