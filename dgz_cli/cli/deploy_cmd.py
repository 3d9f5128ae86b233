"""`dgz deploy`: run a grasp policy on a real hand (or its pty fake, or the MuJoCo sim) safely.

connect hand and arm → identity check → confirm → slow ramp to the thumb-open start pose → 130 policy
steps (wrist command → arm interface: ``none`` logs it, ``sim`` an ideal arm, ``piper`` an AgileX Piper) →
scripted lift → arm holds, hand holds or relaxes. First Ctrl-C stops safely, a second relaxes at once.
``--dry-run`` reads but never writes; ``--replay LOG`` plays a step log on the sim.
"""

from __future__ import annotations

import sys
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from dgz_cli.spec.errors import DgzError


def load_points(path: Path):
    """(P, 3) object points (m, palm frame at the start pose) from .npy or 'x y z' text; see docs/deploy.md."""
    from dgz_cli.runtime.observation import load_object_points

    return load_object_points(path)


def _make_arm(arm: str, spec, asset_root: str | None, arm_port: str | None):
    """``none`` | ``sim`` | ``piper`` | an arm file path → an arm interface (not connected yet)."""
    from dgz_cli.hw.arm import ArmInterface, SimArm

    if arm == "none":
        return ArmInterface()
    if arm != "sim" and arm != "piper" and not arm.endswith((".yaml", ".yml")):
        raise DgzError(f"--arm {arm!r} is not supported", "use --arm none, sim, piper, or a path to an arm file")
    from dgz_cli.runtime.kinematics import HandKinematics

    kin = HandKinematics.for_spec(spec, asset_root)  # the palm frame in the hand's root frame
    kin.pose(kin.rest)
    r_palm, c_palm = kin.palm_frame()
    if arm == "sim":
        return SimArm(r_palm, c_palm)
    from dgz_cli.hw.arm_config import load_arm_config
    from dgz_cli.hw.piper import PiperArm

    cfg = load_arm_config(arm)
    if arm_port:
        cfg = cfg.model_copy(update={"can_port": arm_port})
    return PiperArm(cfg, r_palm, c_palm)


def _warn(console: Console, text: str) -> None:
    console.print(f"[yellow]warning:[/] {escape(text)}", soft_wrap=True, highlight=False)


def _confirm(console: Console, what: str, yes: bool) -> None:
    if yes:
        return
    if not sys.stdin.isatty():
        raise DgzError("refusing to move the hand without confirmation: standard input is not a terminal",
                       "run it in a terminal, or pass --yes once the workspace is clear")
    answer = console.input(f"{escape(what)} Clear the workspace and type 'y' to start: ")
    if answer.strip().lower() not in ("y", "yes"):
        raise DgzError("not confirmed: nothing moved", "answer 'y' to start, or use --dry-run to only read")


def run(hand: str | None, port: str | None, policy: str, object_points: Path | None, dry_run: bool, fake: bool,
        yes: bool, log: Path | None, on_exit: str, replay: Path | None, console: Console, *, rate_hz: float = 20.0,
        grasp_steps: int = 130, lift_steps: int = 30, asset_root: str | None = None,
        allow_privileged: bool = False, arm: str = "none", arm_port: str | None = None) -> int:
    from dgz_cli.hw.factory import SIM_HAND, load_hand, make_driver
    from dgz_cli.runtime.loop import RunConfig, Runner
    from dgz_cli.runtime.observation import HardwareObservation
    from dgz_cli.runtime.policy import load_policy, privileged_needs
    from dgz_cli.runtime.pregrasp import deploy_start_pose
    from dgz_cli.runtime.rate import InterruptGuard
    from dgz_cli.runtime.steplog import StepLogger
    from dgz_cli.runtime.steplog import replay as replay_log
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    if replay is not None:
        summary = replay_log(replay, asset_root=asset_root)
        console.print(f"replayed {summary['steps']} steps of {escape(str(replay))} on the simulated "
                      f"{summary['spec']}: max tracking error {summary['max_tracking_error']:.4f} rad, final "
                      f"{summary['final_tracking_error']:.4f} rad (logged stop: {summary['logged_reason']})")
        return 0
    if not hand:
        raise DgzError("no --hand given", "name a hand: revo2, inspire, leap (hardware), sim, or a hand file path")
    if on_exit not in ("hold", "relax"):
        raise DgzError(f"--on-exit {on_exit!r} is not supported", "use --on-exit hold or --on-exit relax")
    simulated = hand == "sim" or port == "sim"
    fake_dev = None
    if simulated:
        if fake:
            raise DgzError("--fake starts a fake serial device; the sim backend needs none",
                           "drop --fake (or use --fake with a hardware hand such as revo2)")
        from dgz_cli.hw.sim_hand import SimHand

        spec_ref = SIM_HAND if hand == "sim" else hand
        spec = load_spec(resolve_spec(spec_ref))
        driver = SimHand(spec, asset_root=asset_root, control_dt=1.0 / rate_hz)
        overrides = None
    else:
        cfg, spec = load_hand(hand)
        spec_ref, overrides, driver = cfg.spec, cfg.start_pose, None
        if fake and port:
            raise DgzError(f"--fake starts its own device; --port {port} would be ignored", "drop --port or --fake")
        if not fake and not port:
            raise DgzError(f"no --port given for hand '{hand}'",
                           "pass --port /dev/serial/by-id/...; --fake tries a simulated device, --port sim the sim")
    points = load_points(object_points) if object_points else None
    pol = load_policy(policy, spec, allow_privileged=allow_privileged, asset_root=asset_root)
    needs = privileged_needs(pol)
    if needs:
        _warn(console, f"policy '{policy}' observes {', '.join(needs)}, which this hand cannot measure: fed as "
                       "zeros (--allow-privileged); expect a worse grasp than in simulation")
    if isinstance(getattr(pol, "observation_builder", None), HardwareObservation) and points is None:
        raise DgzError(f"policy '{policy}' needs the object: no --object-points given",
                       "pass --object-points FILE: (P, 3) points in metres in the palm frame at the start pose")
    start, note = deploy_start_pose(spec, overrides, asset_root)
    if note:
        _warn(console, note)
    arm_if = _make_arm(arm, spec, asset_root, arm_port)
    cfg_run = RunConfig(rate_hz=rate_hz, grasp_steps=grasp_steps, lift_steps=lift_steps, on_exit=on_exit,
                        dry_run=dry_run, arm=arm_if.name)
    logger = StepLogger(log)
    try:
        if fake:
            from dgz_cli.hw.fakes import fake_for

            fake_dev = fake_for(cfg).start()
            port = fake_dev.port
        if driver is None:
            driver = make_driver(cfg, spec, port)
        with driver:
            info = driver.info
            where = "fake device " + port if fake_dev else ("MuJoCo" if simulated else port)
            console.print(f"connected {escape(hand)} on {escape(where)}: {escape(info.summary())}")
            console.print(f"arm {arm_if.name}: {escape(arm_if.connect())}")
            if not dry_run and (not simulated or arm_if.name == "piper"):
                moves = "the arm follows the wrist command, " if arm_if.name == "piper" else ""
                _confirm(console, f"The hand on {port or 'sim'} will ramp slowly to its start pose, run policy "
                                  f"'{policy}' for {grasp_steps} steps ({moves}then a {lift_steps}-step lift), "
                                  f"then {on_exit} at the end.", yes)
            logger.header(hand=hand, spec=spec_ref, joints=driver.joint_names, nodes=[n.id for n in spec.nodes],
                          rate_hz=rate_hz, port=port or "sim", identity=info.identity, policy=policy,
                          dry_run=dry_run, on_exit=on_exit, arm=arm_if.name, fake=bool(fake_dev),
                          start_pose=start, privileged_zeroed=needs)
            mode = "dry run (reads only)" if dry_run else "running"
            console.print(f"{mode}: {grasp_steps} grasp + {lift_steps} lift steps at {rate_hz:g} Hz — "
                          "Ctrl-C stops safely, a second Ctrl-C relaxes at once")
            context = {"object_points": points}
            with InterruptGuard() as guard:
                result = Runner(driver, spec, pol, cfg_run, logger=logger, guard=guard, context=context,
                                arm=arm_if).run(start)
    finally:
        logger.close()
        arm_if.close()
        if fake_dev is not None:
            fake_dev.stop()
    stats = (f"{result.steps} steps, ramp {result.ramp_steps}, {result.overruns} overruns, "
             f"{result.bus_errors} bus errors, exit action: {result.exit_action}"
             + (f", arm: {result.arm_exit}" if arm_if.name != "none" else ""))
    if result.ok:
        console.print(f"[green]done[/]: {escape(stats)}" + (f"; log {escape(str(log))}" if log else ""))
    else:
        hint = f" [dim]— {escape(result.hint)}[/]" if result.hint else ""
        console.print(f"[bold red]stopped:[/] {escape(result.reason)}{hint}", soft_wrap=True)
        console.print(escape(stats))
    return result.exit_code
