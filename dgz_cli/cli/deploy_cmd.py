"""`dgz deploy`: run a grasp policy on a real hand (or its pty fake, or the MuJoCo sim) safely.

connect → identity check → confirm → slow ramp to the start pose → 130 policy steps → scripted lift
(arm interface ``none``: the lift command is logged) → hold or relax. First Ctrl-C stops safely, a second
relaxes at once. ``--dry-run`` reads but never writes; ``--replay LOG`` plays a step log on the sim.
"""

from __future__ import annotations

import sys
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from dgz_cli.spec.errors import DgzError


def load_points(path: Path):
    """An object point cloud (K × 3, metres, robot base frame) from .npy or a text file (x y z per line)."""
    import numpy as np

    path = Path(path)
    if not path.is_file():
        raise DgzError(f"{path}: no such point-cloud file", "pass a .npy or text file with one 'x y z' per line")
    try:
        if path.suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        else:
            text = path.read_text(encoding="utf-8").replace(",", " ")
            pts = np.loadtxt(text.splitlines(), ndmin=2)
    except (ValueError, OSError) as exc:
        raise DgzError(f"{path}: cannot read points ({exc})", "use .npy (K×3 float) or 'x y z' text lines") from None
    pts = np.asarray(pts, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise DgzError(f"{path}: expected K×3 finite points, got shape {pts.shape}", "export x, y, z columns only")
    return pts


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
        allow_privileged: bool = False) -> int:
    from dgz_cli.hw.factory import SIM_HAND, load_hand, make_driver
    from dgz_cli.runtime.loop import RunConfig, Runner
    from dgz_cli.runtime.mapping import start_pose
    from dgz_cli.runtime.policy import load_policy
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
        start = start_pose(spec)
    else:
        cfg, spec = load_hand(hand)
        spec_ref = cfg.spec
        if fake:
            if port:
                raise DgzError(f"--fake starts its own device; --port {port} would be ignored", "drop --port or --fake")
            from dgz_cli.hw.fakes import fake_for

            fake_dev = fake_for(cfg).start()
            port = fake_dev.port
        elif not port:
            raise DgzError(f"no --port given for hand '{hand}'",
                           "pass --port /dev/serial/by-id/...; --fake tries a simulated device, --port sim the sim")
        driver = make_driver(cfg, spec, port)
        start = start_pose(spec, cfg.start_pose)
    context = {"object_points": load_points(object_points) if object_points else None}
    pol = load_policy(policy, spec, allow_privileged=allow_privileged)
    logger = StepLogger(log)
    cfg_run = RunConfig(rate_hz=rate_hz, grasp_steps=grasp_steps, lift_steps=lift_steps, on_exit=on_exit,
                        dry_run=dry_run)
    try:
        with driver:
            info = driver.info
            where = "fake device " + port if fake_dev else ("MuJoCo" if simulated else port)
            console.print(f"connected {escape(hand)} on {escape(where)}: {escape(info.summary())}")
            if not dry_run and not simulated:
                _confirm(console, f"The hand on {port} will ramp slowly to its start pose, run policy '{policy}' "
                                  f"for {grasp_steps} steps, then {on_exit} at the end.", yes)
            logger.header(hand=hand, spec=spec_ref, joints=driver.joint_names, nodes=[n.id for n in spec.nodes],
                          rate_hz=rate_hz, port=port or "sim", identity=info.identity, policy=policy,
                          dry_run=dry_run, on_exit=on_exit, arm="none", fake=bool(fake_dev))
            mode = "dry run (reads only)" if dry_run else "running"
            console.print(f"{mode}: {grasp_steps} grasp + {lift_steps} lift steps at {rate_hz:g} Hz — "
                          "Ctrl-C stops safely, a second Ctrl-C relaxes at once")
            with InterruptGuard() as guard:
                result = Runner(driver, spec, pol, cfg_run, logger=logger, guard=guard, context=context).run(start)
    finally:
        logger.close()
        if fake_dev is not None:
            fake_dev.stop()
    stats = (f"{result.steps} steps, ramp {result.ramp_steps}, {result.overruns} overruns, "
             f"{result.bus_errors} bus errors, exit action: {result.exit_action}")
    if result.ok:
        console.print(f"[green]done[/]: {escape(stats)}" + (f"; log {escape(str(log))}" if log else ""))
    else:
        hint = f" [dim]— {escape(result.hint)}[/]" if result.hint else ""
        console.print(f"[bold red]stopped:[/] {escape(result.reason)}{hint}", soft_wrap=True)
        console.print(escape(stats))
    return result.exit_code
