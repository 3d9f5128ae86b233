"""The MuJoCo backend of ``dgz deploy --hand sim``: the evaluation scene behind the hardware interfaces.

One :class:`~dgz_cli.sim.env.GraspEnv` slot (hand on its 6-DoF wrist, object, table; the same scene, reset
and physics as ``dgz eval``) stands in for the hand (:class:`SimSceneHand`, a ``HandDriver``), the arm
(:class:`SimSceneArm`) and the camera (:class:`SimSceneObservation`: the simulator's observation, with the
privileged inputs a simulator has). The runtime drives it through exactly the code that drives a real hand
(policy, safety filter, contract scaling, phases), so an episode here reproduces ``dgz eval``'s episode of
the same hand, object and seed step for step; ``tests/test_sim_runtime_parity.py`` keeps it so.

Physics advances one control period on each ``read_state()`` after commands were sent (the env's step
split at the point where the runtime reads), on a simulated clock (:class:`SimClock`): no real-time pacing.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.hw.arm import ArmInterface
from dgz_cli.hw.driver import DeviceInfo, HandDriver, HandState
from dgz_cli.runtime.types import StepInput
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.models import HandSpec


class SimClock:
    """A clock for :class:`~dgz_cli.runtime.rate.RateLoop` that only moves when the loop sleeps."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, dt: float) -> None:
        self.now += max(0.0, dt)


class SimScene:
    """The shared env slot: ``spec`` × ``obj`` under ``cfg`` (the policy's env config), reset with ``seed``;
    ``view``: a distilled student's hardware perturbations (the ones ``dgz eval`` applies to it)."""

    def __init__(self, spec: HandSpec, obj, cfg: EnvConfig, seed: int = 0, asset_root: str | None = None,
                 view=None) -> None:
        from dgz_cli.sim.evaluate import make_env

        self.env = make_env([(spec, obj)], cfg, seed=seed, asset_root=asset_root, threads=1, view=view)
        self.seed = seed
        self.obs: dict | None = None
        self.pending = False
        self.episode: dict | None = None  # the finished episode's record (success, max_rise, ...)

    def reset(self) -> None:
        self.obs = self.env.reset(self.seed)
        self.pending = False
        self.episode = None

    def flush(self) -> None:
        """Run the physics of the commands sent since the last flush (one control period)."""
        if not self.pending:
            return
        self.pending = False
        self.obs, _, _, _, info = self.env.advance()
        if 0 in info["episode"]:
            self.episode = info["episode"][0]

    def close(self) -> None:
        self.env.close()


class SimSceneHand(HandDriver):
    protocol = "mujoco-scene"

    def __init__(self, scene: SimScene, spec: HandSpec) -> None:
        super().__init__(spec, "sim")
        self.scene = scene
        self.n = len(spec.joints)
        self.lo = scene.env.limits[0, :self.n, 0].copy()
        self.hi = scene.env.limits[0, :self.n, 1].copy()

    def connect(self) -> DeviceInfo:
        self.scene.reset()
        self.connected = True
        slot = self.scene.env.slots[0]
        self.info = DeviceInfo("sim", self.protocol, {"spec": self.spec.name, "object": slot.obj.name,
                                                      "seed": str(self.scene.seed)})
        return self.info

    def enable(self) -> None:
        pass

    def read_state(self) -> HandState:
        self.scene.flush()
        env = self.scene.env
        q = env.buf["q"][0, :self.n].copy()
        stamp = float(env.t[0]) / env.cfg.contract.episode.control_hz
        return HandState(q=q, effort=np.zeros(self.n), effort_kind="sim_N·m", stamp=stamp,
                         fingerprint=np.concatenate([[stamp], q]).tobytes())

    def write_targets(self, q: np.ndarray) -> None:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,) or not np.all(np.isfinite(q)):
            raise ValueError(f"expected {self.n} finite joint values")
        env = self.scene.env
        targets = env.targets.copy()
        targets[0, :self.n] = np.clip(q, self.lo, self.hi)
        env.set_targets(targets)  # (the env's r_pen needs the primitive actions; deploy reports no reward)
        self.scene.pending = True

    def hold(self) -> None:
        self.scene.flush()  # finish the last commanded step: the episode ends there

    def relax(self) -> None:
        self.scene.flush()

    def torque_off(self) -> None:
        pass

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def close(self) -> None:
        self.connected = False


class SimSceneArm(ArmInterface):
    """The scene's wrist as the arm: commands (palm frame) and the lift go to the env's wrist targets."""

    name = "sim-scene"
    moves = True

    def __init__(self, scene: SimScene) -> None:
        self.scene = scene

    def connect(self) -> str:
        return "the evaluation scene's 6-DoF wrist"

    def command(self, delta: np.ndarray, frame: str = "palm", lift: float = 0.0) -> dict:
        if frame != "palm":
            raise ValueError("the scene's wrist takes palm-frame commands")
        self.scene.env.move_wrist(np.asarray(delta, dtype=float).reshape(1, -1), np.array([lift]))
        self.scene.pending = True
        return {}

    def hold(self) -> str:
        return "hold"


class SimSceneObservation:
    """The simulator's own observation of the scene (the one ``dgz eval`` feeds the policy)."""

    def __init__(self, scene: SimScene) -> None:
        self.scene = scene

    def reset(self, spec: HandSpec, context: dict) -> None:
        pass

    def build(self, step: StepInput) -> dict:
        return {k: np.array(v, copy=True) for k, v in self.scene.obs.items()}
