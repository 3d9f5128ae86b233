"""The control loop end to end against the pty fakes and the sim: tracking, faults → safe stop, Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pytest
from rich.console import Console

from dgz_cli.cli import deploy_cmd
from dgz_cli.hw.factory import load_hand, make_driver
from dgz_cli.hw.fakes import fake_for
from dgz_cli.runtime import bench
from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.mapping import start_pose
from dgz_cli.runtime.policy import ClosePolicy
from dgz_cli.runtime.rate import InterruptGuard
from dgz_cli.runtime.steplog import StepLogger, read_log, replay
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.spec.errors import DgzError

RATE = 100.0  # tests run the real loop faster than the 20 Hz default


def fast(grasp: int = 120, lift: int = 30, hold_s: float = 0.4) -> ControlContract:
    """The default contract's scales at RATE Hz (physics 400 Hz) with the given phases."""
    return ControlContract(episode=EpisodeProtocol(control_hz=RATE, grasp_steps=grasp, lift_steps=lift, hold_s=hold_s))


FAST = fast()


def console() -> Console:
    return Console(width=200, force_terminal=False, record=True)


@pytest.mark.parametrize("hand", ["revo2", "inspire", "leap"])
def test_fake_deploy_tracks_targets(tmp_path, hand):
    log = tmp_path / f"{hand}.jsonl"
    out = console()
    code = deploy_cmd.run(hand, None, "close", None, False, True, True, log, "hold", None, out, contract=FAST)
    assert code == 0, out.export_text()
    header, steps, end = read_log(log)
    assert header["hand"] == hand and header["fake"] and header["arm"] == "none"
    assert header["contract"]["episode"]["control_hz"] == RATE
    phases = {p: [s for s in steps if s["phase"] == p] for p in ("grasp", "lift", "hold")}
    assert [len(v) for v in phases.values()] == [120, 30, 40] and end["ok"] and end["exit_action"] == "hold"
    assert all(s["lift"] == pytest.approx(0.5 / 30, abs=1e-6) for s in phases["lift"])  # the protocol's lift, logged only
    assert all(s["lift"] == 0 for s in phases["grasp"] + phases["hold"])
    grasp = phases["grasp"]
    assert grasp[-1]["target"] != grasp[0]["target"]  # the hand closed
    last = steps[-1]
    assert np.max(np.abs(np.array(last["target"]) - np.array(last["measured"]))) < 0.02
    assert {"action", "target", "measured", "effort", "loop_ms", "bus_errors", "wrist_sent"} <= set(last)


def test_fake_deploy_scripted_grasp_needs_and_uses_the_object(tmp_path):
    with pytest.raises(DgzError, match="needs the object"):
        deploy_cmd.run("revo2", None, "scripted", None, False, True, True, None, "hold", None, console(), contract=FAST)
    log = tmp_path / "s.jsonl"
    assert deploy_cmd.run("revo2", None, "scripted", "sphere", False, True, True, log, "hold", None, console(),
                          contract=FAST) == 0
    steps = read_log(log)[1]
    grasp = [s for s in steps if s["phase"] == "grasp"]
    assert grasp[0]["action"][2] == 1.0  # approach along the palm normal first
    assert max(grasp[-1]["action"][6:]) == 1.0  # then close (the palm never moves: --arm none, so it stalls)


def test_sim_deploy_and_replay(tmp_path):
    log = tmp_path / "sim.jsonl"
    assert deploy_cmd.run("sim", None, "scripted", None, False, False, False, log, "relax", None,
                          console()) == 0  # the sim needs no confirmation
    summary = replay(log)
    assert summary["spec"] == "dgz_tri" and summary["steps"] == 190
    assert summary["final_tracking_error"] < 0.03
    out = console()
    assert deploy_cmd.run("sim", None, "scripted", None, False, False, False, None, "hold", log, out) == 0
    assert "replayed 190 steps" in out.export_text()


def test_dry_run_never_writes(tmp_path):
    cfg, spec = load_hand("revo2")
    with fake_for(cfg) as fake, make_driver(cfg, spec, fake.port) as driver:
        res = Runner(driver, spec, ClosePolicy(spec), RunConfig(contract=fast(10, 2, 0.0), dry_run=True)).run(
            start_pose(spec))
        assert res.ok and res.exit_action == "none" and fake.writes == []


def test_refuses_to_move_without_tty_or_yes():
    with pytest.raises(DgzError, match="standard input is not a terminal") as info:
        deploy_cmd.run("inspire", None, "close", None, False, True, False, None, "hold", None, console())
    assert "--yes" in info.value.hint


def test_cli_argument_errors(tmp_path):
    with pytest.raises(DgzError, match="no --port given for hand 'revo2'"):
        deploy_cmd.run("revo2", None, "scripted", None, False, False, True, None, "hold", None, console())
    with pytest.raises(DgzError, match="--on-exit 'drop'"):
        deploy_cmd.run("sim", None, "scripted", None, False, False, True, None, "drop", None, console())
    with pytest.raises(DgzError, match="no hardware driver file for hand 'allegro'"):
        deploy_cmd.run("allegro", "/dev/ttyUSB0", "scripted", None, False, False, True, None, "hold", None, console())
    bad = tmp_path / "pts.txt"
    bad.write_text("1 2\n")
    with pytest.raises(DgzError, match="expected K×3"):
        deploy_cmd.run("revo2", None, "scripted", bad, False, True, True, None, "hold", None, console())
    good = tmp_path / "pts.npy"
    np.save(good, np.array([[0.0, 0.0, 0.1], [0.02, 0.0, 0.1]]))
    assert deploy_cmd.run("revo2", None, "scripted", good, True, True, True, None, "hold", None, console(),
                          contract=fast(3, 0, 0.0)) == 0
    with pytest.raises(DgzError, match="--sim-hand picks the hand"):
        deploy_cmd.run("revo2", None, "close", None, False, True, True, None, "hold", None, console(), sim_hand="leap")
    with pytest.raises(DgzError, match="--sim-object 'ycb45' names 45 objects"):
        deploy_cmd.run("sim", None, "close", None, False, False, True, None, "hold", None, console(),
                       sim_object="ycb45", asset_root=os.environ.get("DGZ_ASSET_ROOT"))


class Injector(ClosePolicy):
    """The blind-close policy, plus an action at step ``at`` (set a fault, slow down, emit NaN, Ctrl-C ...)."""

    def __init__(self, spec, at, what) -> None:
        super().__init__(spec, FAST)
        self.at, self.what = at, what

    def act(self, obs):
        a = super().act(obs)
        if self.k - 1 >= self.at:
            return self.what(a)
        return a


def run_with(hand, what, at=5, on_exit="hold", **fake_kw):
    cfg, spec = load_hand(hand)
    with fake_for(cfg, **fake_kw) as fake, make_driver(cfg, spec, fake.port) as driver:
        policy = Injector(spec, at, lambda a: what(fake, a))
        with InterruptGuard() as guard:
            res = Runner(driver, spec, policy, RunConfig(contract=FAST, on_exit=on_exit), guard=guard).run()
        return res, fake


def set_fault(name):
    def what(fake, a):
        fake.fault = name
        return a
    return what


@pytest.mark.parametrize("hand", ["revo2", "inspire", "leap"])
@pytest.mark.parametrize("fault,reason", [
    ("no_answer", "3 bus errors in a row; last: .*(no reply|no status packet)"),
    ("crc", "3 bus errors in a row; last: .*CRC error"),
    ("exception", "(exception 4 \\(slave device failure\\)|hardware alert)"),
    ("stale", "feedback frozen: 3 reads in a row"),
    ("disconnect", "serial port failed"),
])
def test_fault_injection_stops_safely(hand, fault, reason):
    res, fake = run_with(hand, set_fault(fault))
    assert not res.ok and res.exit_code == 1
    assert pytest.approx(res.steps, abs=4) == 6 and res.steps < 130
    import re

    assert re.search(reason, res.reason), res.reason
    assert "\n" not in res.reason and res.hint
    if fault == "stale":
        assert res.exit_action == "hold"  # the bus still works: the hand holds where it is
    elif fault == "disconnect":
        assert res.exit_action == "none (hand unreachable)"
    elif hand == "leap":
        assert res.exit_action == "torque off"  # sync-write needs no reply: torque off still goes out


def test_single_transient_error_is_tolerated():
    calls = []

    def once(fake, a):  # corrupt replies from one step's write to the next step's read, then recover
        calls.append(1)
        fake.fault = "crc" if len(calls) == 1 else None
        return a
    res, _ = run_with("revo2", once, at=10)
    assert res.ok and res.bus_errors == 2, res.reason  # 2 in a row < max_bus_errors (3)


def test_sustained_overrun_stops():
    def slow(fake, a):
        time.sleep(0.015)  # > 10 ms period
        return a
    res, _ = run_with("revo2", slow, at=3)
    assert not res.ok and "late 5 steps in a row" in res.reason and res.overruns >= 5
    assert res.exit_action == "hold"


def test_nan_action_stops_and_relaxes_when_asked():
    res, fake = run_with("revo2", lambda fake, a: a * np.nan, on_exit="relax")
    assert not res.ok and "non-finite action" in res.reason and res.exit_action == "relax"
    assert res.steps == 5


def test_policy_exception_still_stops_safely():
    def boom(fake, a):
        raise RuntimeError("shape mismatch in layer 3")
    res, _ = run_with("inspire", boom)
    assert not res.ok and "RuntimeError in the control loop: shape mismatch" in res.reason
    assert res.exit_action == "hold"


def test_first_ctrl_c_stops_second_relaxes():
    def one(fake, a):
        os.kill(os.getpid(), signal.SIGINT)
        return a
    res, _ = run_with("revo2", one, at=4)
    assert res.exit_code == 130 and res.reason == "stopped by Ctrl-C after 5 steps" and res.exit_action == "hold"

    def two(fake, a):
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        return a
    res, fake = run_with("leap", two, at=4)
    assert res.exit_code == 130 and "second Ctrl-C" in res.reason and res.exit_action == "relax"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
@pytest.mark.parametrize("on_exit", ["hold", "relax"])
def test_sigterm_and_sighup_stop_like_ctrl_c(sig, on_exit):
    """systemd, docker stop, timeout (SIGTERM) and a closed terminal (SIGHUP): stop at the step boundary, then
    the exit actions (--on-exit honoured), exit code 143; the process is not killed."""
    def once(fake, a):
        os.kill(os.getpid(), sig)
        return a
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    res, fake = run_with("revo2", once, at=4, on_exit=on_exit)
    assert res.exit_code == 143 and res.reason == f"stopped by {sig.name} after 5 steps", res.reason
    assert res.exit_action == on_exit and not res.ok
    assert {s: signal.getsignal(s) for s in before} == before  # the guard puts the previous handlers back
    last_goal = [v for a, v in fake.writes if a == 1022][-1]
    if on_exit == "relax":
        assert all(last_goal[2 * i] == 0 for i in range(6))  # Revo2 relax: open on every finger


def test_second_signal_relaxes_at_once():
    def two(fake, a):
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGHUP)
        return a
    res, _ = run_with("leap", two, at=4)
    assert res.exit_code == 143 and res.reason == "SIGHUP after SIGTERM: relaxing at once" and res.exit_action == "relax"


def test_deploy_on_sigterm_writes_the_end_record_and_returns_143(tmp_path):
    """End to end through `dgz deploy --fake`: the step log's end record and the exit code."""
    from dgz_cli.runtime import policy as policy_mod

    log = tmp_path / "t.jsonl"
    real_act = policy_mod.ClosePolicy.act

    def act(self, obs):
        if getattr(self, "k", 0) == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return real_act(self, obs)

    out = console()
    mp = pytest.MonkeyPatch()
    mp.setattr(policy_mod.ClosePolicy, "act", act)
    try:
        code = deploy_cmd.run("inspire", None, "close", None, False, True, True, log, "relax", None, out, contract=FAST)
    finally:
        mp.undo()
    assert code == 143, out.export_text()
    header, steps, end = read_log(log)
    assert end["exit_code"] == 143 and end["exit_action"] == "relax" and "stopped by SIGTERM" in end["reason"]
    assert "stopped by SIGTERM" in out.export_text()


def test_step_log_is_jsonl(tmp_path):
    cfg, spec = load_hand("inspire")
    path = tmp_path / "run.jsonl"
    with fake_for(cfg) as fake, make_driver(cfg, spec, fake.port) as driver:
        log = StepLogger(path)
        log.header(spec="inspire", joints=driver.joint_names, rate_hz=RATE)
        Runner(driver, spec, ClosePolicy(spec), RunConfig(contract=fast(4, 1, 0.0)), logger=log).run(start_pose(spec))
        log.close()
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [r["type"] for r in lines] == ["header"] + ["step"] * 6 + ["end"]  # 1 ramp + 4 grasp + 1 lift
    assert lines[-1]["ok"] and len(lines[2]["effort"]) == 6


def test_bench_returns_json():
    result = bench.run("revo2", steps=4)
    json.dumps(result)
    assert result["ok"] and result["steps"] == 4
    assert {"mean_period_ms", "p99_jitter_ms", "max_period_ms", "overruns", "mean_read_ms"} <= set(result)


class Normalized:
    """A network-style policy: outputs in [-1, 1], scaled by the contract (0.01 wrist, 0.015 fingers)."""

    def __init__(self, spec) -> None:
        self.n = 6 + 3 * len(spec.nodes)

    def act(self, obs):
        assert obs["q"] is not None and obs["object_point"] is not None
        return np.ones(self.n)


def test_normalized_policy_on_sim(tmp_path):
    from dgz_cli.hw.factory import make_sim_driver

    hand = make_sim_driver("dgz_tri", control_dt=1 / RATE)
    spec = hand.spec
    log = StepLogger(tmp_path / "n.jsonl")
    log.header(spec="dgz_tri", joints=hand.joint_names, rate_hz=RATE)
    with hand:
        res = Runner(hand, spec, Normalized(spec), RunConfig(contract=fast(2, 0, 0.0)), logger=log,
                     context={"object_points": np.array([[0.0, 0.05, 0.1], [0.0, 0.07, 0.1]])}).run()
    log.close()
    assert res.ok, res.reason
    steps = read_log(tmp_path / "n.jsonl")[1]
    names = hand.joint_names
    k = names.index("index_mcp")
    assert steps[0]["wrist_cmd"][:3] == pytest.approx([0.01] * 3)
    assert steps[1]["target"][k] - steps[0]["target"][k] == pytest.approx(0.015)


def test_policy_brings_its_observation_builder():
    class Builder:
        def reset(self, spec, context):
            self.n = 0

        def build(self, step):
            self.n += 1
            return {"custom": step.k}

    class WithBuilder(ClosePolicy):
        observation_builder = Builder()

        def act(self, obs):
            assert set(obs) == {"custom"}
            return super().act(obs)

    from dgz_cli.hw.factory import make_sim_driver

    with make_sim_driver("dgz_tri") as hand:
        policy = WithBuilder(hand.spec)
        res = Runner(hand, hand.spec, policy, RunConfig(contract=fast(3, 0, 0.0))).run()
    assert res.ok and policy.observation_builder.n == 3


def test_guidance_stop_gap_needs_the_palm_distance_in_the_observation():
    """A contract whose guidance stops near the object reads the palm → surface distance from the observation's
    nodes; an observation without them ends in a safe stop that says so (not a traceback, no guessed gap)."""
    from dgz_cli.hw.factory import make_sim_driver
    from dgz_cli.spec.contract import WristGuidance

    contract = fast(3, 0, 0.0).model_copy(update=dict(guidance=WristGuidance(gain=0.05, stop_gap=0.05)))

    class GlobalOnly:
        def reset(self, spec, context):
            pass

        def build(self, step):
            return {"global": np.zeros((1, contract.observation.global_dim))}

    class Policy(Normalized):
        observation_builder = GlobalOnly()

        def act(self, obs):
            return np.zeros(self.n)

    with make_sim_driver("dgz_tri") as hand:
        res = Runner(hand, hand.spec, Policy(hand.spec), RunConfig(contract=contract),
                     grasp_offset=np.zeros(3)).run()
    assert not res.ok and res.steps == 0 and "no palm → surface distance" in res.reason
