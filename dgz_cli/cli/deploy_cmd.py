"""`dgz deploy`: run a grasp policy on a real hand (or its pty fake, or the MuJoCo sim) safely.

connect hand and arm → identity check → confirm → slow ramp to the contract's start pose → the policy's
control-contract episode (grasp, lift, hold at its rate; wrist command → arm interface: ``none`` logs it,
``sim`` an ideal arm, ``piper`` an AgileX Piper) → arm holds, hand holds or relaxes. First Ctrl-C stops
safely, a second relaxes at once. ``--hand sim`` runs the evaluation scene (MuJoCo) behind the same loop.
``--dry-run`` reads but never writes; ``--replay LOG`` plays a step log on the sim.
"""

from __future__ import annotations

import json
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


def policy_env_config(policy: str, contract=None):
    """The env config (and so the control contract) a policy runs under: a checkpoint's own, read without
    torch; the built-in and plug-in policies use ``contract`` (default: the default contract)."""
    from dgz_cli.spec.envconfig import EnvConfig

    if policy in ("scripted", "close") or ":" in policy:
        return EnvConfig() if contract is None else EnvConfig(contract=contract)
    from dgz_cli.rl.checkpoint import read_meta, resolve_checkpoint

    from dgz_cli.spec.catalog import policy_ref

    directory = resolve_checkpoint(policy_ref(policy))  # a shipped name resolves in a wheel install too
    return read_meta(directory).env if directory is not None else EnvConfig()


def policy_view(policy: str):
    """A distilled student's hardware view (the perturbations ``dgz eval`` applies to it), or None."""
    if policy in ("scripted", "close") or ":" in policy:
        return None
    from dgz_cli.rl.checkpoint import read_meta, resolve_checkpoint
    from dgz_cli.spec.catalog import policy_ref

    directory = resolve_checkpoint(policy_ref(policy))
    student = read_meta(directory).student if directory is not None else None
    return None if student is None else student.distill.view


def run(hand: str | None, port: str | None, policy: str, object_points: Path | None, dry_run: bool, fake: bool,
        yes: bool, log: Path | None, on_exit: str, replay: Path | None, console: Console, *,
        asset_root: str | None = None, allow_privileged: bool = False, arm: str = "none", arm_port: str | None = None,
        sim_hand: str | None = None, sim_object: str = "sphere", seed: int = 0, contract=None) -> int:
    """``contract``: the control contract for the built-in and plug-in policies (rate, phases, scales;
    default: the default contract); a checkpoint always runs under its own."""
    from dgz_cli.hw.factory import SIM_HAND, load_hand, make_driver
    from dgz_cli.runtime.loop import RunConfig, Runner
    from dgz_cli.runtime.observation import HardwareObservation
    from dgz_cli.runtime.policy import load_policy
    from dgz_cli.runtime.types import privileged_needs
    from dgz_cli.runtime.pregrasp import deploy_start_pose
    from dgz_cli.runtime.rate import InterruptGuard
    from dgz_cli.runtime.sim_backend import SimClock
    from dgz_cli.runtime.steplog import StepLogger
    from dgz_cli.runtime.steplog import replay as replay_log
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec

    if replay is not None:
        summary = replay_log(replay, asset_root=asset_root)
        console.print(f"replayed {summary['steps']} steps of {escape(str(replay))} on the simulated "
                      f"{escape(str(summary['spec']))}: max tracking error {summary['max_tracking_error']:.4f} rad, final "
                      f"{summary['final_tracking_error']:.4f} rad (logged stop: {escape(str(summary['logged_reason']))})")
        return 0
    if not hand:
        raise DgzError("no --hand given", "name a hand: revo2, inspire, leap (hardware), sim, or a hand file path")
    if on_exit not in ("hold", "relax"):
        raise DgzError(f"--on-exit {on_exit!r} is not supported", "use --on-exit hold or --on-exit relax")
    simulated = hand == "sim"       # the evaluation scene (hand on its wrist, object, table)
    hand_only = port == "sim" and not simulated  # the hand alone in MuJoCo behind the hardware code path
    if sim_hand is not None and hand != "sim":
        raise DgzError("--sim-hand picks the hand of --hand sim", "drop --sim-hand, or use --hand sim")
    env_cfg = policy_env_config(policy, contract)
    contract = env_cfg.contract
    fake_dev = scene = None
    clock, sleep = None, None
    if simulated:
        if fake:
            raise DgzError("--fake starts a fake serial device; the sim backend needs none",
                           "drop --fake (or use --fake with a hardware hand such as revo2)")
        if arm != "none":
            raise DgzError(f"--arm {arm} with the MuJoCo backend: the scene's own wrist is the arm", "drop --arm")
        from dgz_cli.runtime.sim_backend import SimScene, SimSceneArm, SimSceneHand, SimSceneObservation
        from dgz_cli.sim.objects import resolve_objects

        spec_ref = sim_hand or SIM_HAND
        spec = load_spec(resolve_spec(spec_ref))
        objs = resolve_objects(sim_object, asset_root)
        if len(objs) != 1:
            raise DgzError(f"--sim-object '{sim_object}' names {len(objs)} objects", "give exactly one object name")
        scene = SimScene(spec, objs[0], env_cfg, seed=seed, asset_root=asset_root, view=policy_view(policy))
        driver, arm_if = SimSceneHand(scene, spec), SimSceneArm(scene)
        pol = load_policy(policy, spec, contract=contract, observation_builder=SimSceneObservation(scene),
                          grasp_offset=scene.env.grasp_offset[0], asset_root=asset_root)
        overrides, start, points = None, None, None  # the scene's reset pose is the protocol's start
        grasp_offset = scene.env.grasp_offset[0]
        sim_clock = SimClock()
        clock, sleep = sim_clock, sim_clock.sleep
    else:
        if hand_only:
            from dgz_cli.hw.config import load_hand_config
            from dgz_cli.hw.sim_hand import SimHand

            if fake:
                raise DgzError("--fake starts a fake serial device; --port sim needs none", "drop --fake or --port sim")
            try:
                hand_cfg = load_hand_config(hand)
                spec_ref, overrides = hand_cfg.spec, hand_cfg.start_pose
            except DgzError:  # not a hardware hand: any shipped hand or spec file
                spec_ref, overrides = hand, None
            spec = load_spec(resolve_spec(spec_ref))
            driver = SimHand(spec, asset_root=asset_root, control_dt=1.0 / contract.episode.control_hz)
            sim_clock = SimClock()  # the simulated hand advances on reads: no real-time pacing
            clock, sleep = sim_clock, sim_clock.sleep
        else:
            cfg, spec = load_hand(hand)
            spec_ref, overrides, driver = cfg.spec, cfg.start_pose, None
        if fake and port:
            raise DgzError(f"--fake starts its own device; --port {port} would be ignored", "drop --port or --fake")
        if not fake and not port:
            raise DgzError(f"no --port given for hand '{hand}'",
                           "pass --port /dev/serial/by-id/...; --fake tries a simulated device, --port sim the sim")
        points = load_points(object_points) if object_points else None
        pol = load_policy(policy, spec, contract=contract, allow_privileged=allow_privileged, asset_root=asset_root)
        if isinstance(getattr(pol, "observation_builder", None), HardwareObservation) and points is None:
            raise DgzError(f"policy '{policy}' needs the object: no --object-points given",
                           "pass --object-points FILE ((P, 3) points in metres in the palm frame at the start "
                           "pose) or a built-in object name such as sphere")
        grasp_offset = None
        if contract.guidance.gain > 0:
            from dgz_cli.runtime.observation import grasp_offset_of

            grasp_offset = grasp_offset_of(spec, asset_root)
        start = deploy_start_pose(spec, contract, overrides)
        arm_if = _make_arm(arm, spec, asset_root, arm_port)
    needs = [] if simulated else privileged_needs(pol)
    if needs:
        _warn(console, f"policy '{policy}' observes {', '.join(needs)}, which this hand cannot measure: fed as "
                       "zeros (--allow-privileged); expect a worse grasp than in simulation")
    ep = contract.episode
    cfg_run = RunConfig(contract=contract, on_exit=on_exit, dry_run=dry_run, wrist_filter=not simulated)
    logger = StepLogger(log)
    result = None
    try:
        if fake:
            from dgz_cli.hw.fakes import fake_for

            fake_dev = fake_for(cfg).start()
            port = fake_dev.port
        if driver is None:
            driver = make_driver(cfg, spec, port)
        with driver:
            info = driver.info
            where = "fake device " + port if fake_dev else ("MuJoCo" if simulated or hand_only else port)
            console.print(f"connected {escape(hand)} on {escape(where)}: {escape(info.summary())}")
            console.print(f"arm {escape(str(arm_if.name))}: {escape(arm_if.connect())}")
            phases = f"{ep.grasp_steps} grasp + {ep.lift_steps} lift + {ep.hold_steps} hold steps"
            if not dry_run and (not (simulated or hand_only) or arm_if.name == "piper"):
                moves = "the arm follows the wrist command and lifts, " if arm_if.moves else ""
                _confirm(console, f"The hand on {port} will ramp slowly to its start pose, run policy "
                                  f"'{policy}' for {phases} ({moves}at {ep.control_hz:g} Hz), then {on_exit} at "
                                  "the end.", yes)
            logger.header(hand=hand, spec=spec_ref, joints=driver.joint_names, nodes=[n.id for n in spec.nodes],
                          rate_hz=ep.control_hz, port=port or "sim", identity=info.identity, policy=policy,
                          dry_run=dry_run, on_exit=on_exit, arm=arm_if.name, fake=bool(fake_dev),
                          start_pose=start, privileged_zeroed=needs,
                          contract=json.loads(contract.model_dump_json(by_alias=True)))
            mode = "dry run (reads only)" if dry_run else "running"
            console.print(f"{mode}: {phases} at {ep.control_hz:g} Hz — Ctrl-C stops safely, a second Ctrl-C "
                          "relaxes at once")
            context = {"object_points": points}
            timing = {} if clock is None else {"clock": clock, "sleep": sleep}
            with InterruptGuard() as guard:
                result = Runner(driver, spec, pol, cfg_run, logger=logger, guard=guard, context=context,
                                arm=arm_if, grasp_offset=grasp_offset, **timing).run(start)
    finally:
        logger.close()
        arm_if.close()
        if fake_dev is not None:
            fake_dev.stop()
        if scene is not None:
            scene.close()
    stats = (f"{result.steps} steps, ramp {result.ramp_steps}, {result.overruns} overruns, "
             f"{result.bus_errors} bus errors, exit action: {result.exit_action}"
             + (f", arm: {result.arm_exit}" if arm_if.name != "none" else ""))
    if scene is not None and scene.episode is not None:
        e = scene.episode
        stats += f"; episode {'succeeded' if e['success'] else 'failed'} (object rose {e['max_rise']:.3f} m)"
    if result.ok:
        console.print(f"[green]done[/]: {escape(stats)}" + (f"; log {escape(str(log))}" if log else ""))
    else:
        hint = f" [dim]— {escape(result.hint)}[/]" if result.hint else ""
        console.print(f"[bold red]stopped:[/] {escape(result.reason)}{hint}", soft_wrap=True)
        console.print(escape(stats))
    return result.exit_code
