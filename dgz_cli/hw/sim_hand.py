"""A MuJoCo-simulated hand behind the driver interface (dry runs, replay, CI).

Built from the spec's URDF with :mod:`dgz_cli.spec.urdfxml` (safe parse, visuals dropped, compiler
settings injected; mimic joints become equality constraints), then one position servo per actuated
spec joint is added with ``MjSpec.add_actuator`` (kp 2 N·m/rad, kv 0.05, ctrl range = joint limits).
The palm is fixed, gravity and contacts are off: a dry run checks commands and tracking, not a grasp. Physics runs
at 400 Hz; each ``read_state()`` advances the simulation by one control period (deterministic).
"""

from __future__ import annotations

import numpy as np

from dgz_cli.hw.driver import DeviceInfo, HandDriver, HandState
from dgz_cli.hw.errors import HardwareError
from dgz_cli.spec.catalog import resolve_urdf
from dgz_cli.spec.models import HandSpec
from dgz_cli.spec.kinematics import hand_xml
from dgz_cli.spec.urdfxml import captured_mujoco_warnings


def build_model(spec: HandSpec, asset_root: str | None = None, kp: float = 2.0, kv: float = 0.05,
                timestep: float = 0.0025, gravity: bool = False, contacts: bool = False):
    """(MjModel, actuator ids in spec joint order, qpos addresses in spec joint order)."""
    import mujoco

    urdf = resolve_urdf(spec.provenance.urdf, asset_root)
    with captured_mujoco_warnings():
        try:
            ms = mujoco.MjSpec.from_string(hand_xml(spec, asset_root))
        except ValueError as exc:
            raise HardwareError(f"sim: MuJoCo cannot load {urdf}: {' '.join(str(exc).split())}",
                                f"run `dgz lint {spec.name}` to find the broken element") from None
        ms.option.timestep = timestep
        ms.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        if not gravity:
            ms.option.gravity = [0.0, 0.0, 0.0]
        if not contacts:  # vendor meshes often overlap at rest; a dry run checks the command path
            ms.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        names = {j.name for j in ms.joints}
        for row in spec.joints:
            if row.joint not in names:
                raise HardwareError(f"sim: spec joint '{row.joint}' is not in {urdf.name}",
                                    "the spec and the URDF disagree: re-onboard the hand")
            act = ms.add_actuator()
            act.name = f"dgz_servo_{row.joint}"
            act.target = row.joint
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_position(kp=kp, kv=kv)
            act.ctrllimited = True
            act.ctrlrange = [row.lower, row.upper]
        try:
            model = ms.compile()
        except ValueError as exc:
            raise HardwareError(f"sim: MuJoCo cannot compile {urdf}: {' '.join(str(exc).split())}",
                                f"run `dgz lint {spec.name}`") from None
    acts = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"dgz_servo_{r.joint}") for r in spec.joints]
    qadr = [int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, r.joint)]) for r in spec.joints]
    return model, np.array(acts), np.array(qadr)


class SimHand(HandDriver):
    protocol = "mujoco"

    def __init__(self, spec: HandSpec, asset_root: str | None = None, control_dt: float = 0.05, **model_kw) -> None:
        super().__init__(spec, "sim")
        self.asset_root = asset_root
        self.control_dt = control_dt
        self.model_kw = model_kw
        self.model = self.data = None
        self.lo = np.array([j.lower for j in spec.joints])
        self.hi = np.array([j.upper for j in spec.joints])
        self.enabled = False

    def connect(self) -> DeviceInfo:
        import mujoco

        self.model, self.acts, self.qadr = build_model(self.spec, self.asset_root, **self.model_kw)
        self._gain = self.model.actuator_gainprm[self.acts, 0].copy()
        self._bias = self.model.actuator_biasprm[self.acts, :3].copy()
        self.data = mujoco.MjData(self.model)
        q0 = self.spec.rest_pose()
        self.data.qpos[self.qadr] = q0
        self.data.ctrl[self.acts] = q0
        mujoco.mj_forward(self.model, self.data)
        self._mj = mujoco
        self.substeps = max(1, int(round(self.control_dt / self.model.opt.timestep)))
        self.connected = True
        self.info = DeviceInfo("sim", self.protocol, {"spec": self.spec.name, "joints": str(len(self.acts)),
                                                      "physics": f"{1 / self.model.opt.timestep:.0f} Hz"})
        return self.info

    def enable(self) -> None:
        self.model.actuator_gainprm[self.acts, 0] = self._gain
        self.model.actuator_biasprm[self.acts, :3] = self._bias
        self.enabled = True

    def read_state(self) -> HandState:
        self._mj.mj_step(self.model, self.data, nstep=self.substeps)
        q = self.data.qpos[self.qadr].copy()
        effort = self.data.actuator_force[self.acts].copy()
        fingerprint = np.concatenate([[self.data.time], q]).tobytes()
        return HandState(q=q, effort=effort, effort_kind="sim_N·m", stamp=self.data.time, fingerprint=fingerprint)

    def write_targets(self, q: np.ndarray) -> None:
        q = np.asarray(q, dtype=float)
        if q.shape != self.lo.shape or not np.all(np.isfinite(q)):
            raise ValueError(f"expected {len(self.lo)} finite joint values")
        self.data.ctrl[self.acts] = np.clip(q, self.lo, self.hi)

    def hold(self) -> None:
        self.data.ctrl[self.acts] = self.data.qpos[self.qadr]

    def relax(self) -> None:
        self.torque_off()

    def torque_off(self) -> None:
        self.model.actuator_gainprm[self.acts, 0] = 0.0
        self.model.actuator_biasprm[self.acts, :3] = 0.0
        self.enabled = False

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def close(self) -> None:
        self.connected = False
