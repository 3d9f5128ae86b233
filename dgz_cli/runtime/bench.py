"""Loop-timing benchmark: the real control loop (20 Hz, blind-close policy) against a hand's pty fake or the sim.

``run(hand, steps)`` → a JSON-able dict: mean period, p99 jitter (|period − nominal|), worst period,
overruns and the mean time of one read and one write. Timing numbers depend on the machine; the
test suite only checks the shape of the result, never the numbers.
"""

from __future__ import annotations

import time

import numpy as np

from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.policy import ClosePolicy
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol


class _TimedDriver:
    """Wraps a driver to time its read and write calls."""

    def __init__(self, inner) -> None:
        self.inner, self.reads, self.writes = inner, [], []

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def read_state(self):
        t = time.perf_counter()
        try:
            return self.inner.read_state()
        finally:
            self.reads.append(time.perf_counter() - t)

    def write_targets(self, q):
        t = time.perf_counter()
        try:
            return self.inner.write_targets(q)
        finally:
            self.writes.append(time.perf_counter() - t)


def run(hand: str = "revo2", steps: int = 200, rate_hz: float = 20.0) -> dict:
    from dgz_cli.hw.factory import SIM_HAND, load_hand, make_driver, make_sim_driver

    fake = None
    if hand == "sim":
        driver = make_sim_driver(SIM_HAND, control_dt=1.0 / rate_hz)
        spec = driver.spec
    else:
        from dgz_cli.hw.fakes import fake_for

        cfg, spec = load_hand(hand)
        fake = fake_for(cfg).start()
        driver = make_driver(cfg, spec, fake.port)
    try:
        with driver:
            timed = _TimedDriver(driver)
            contract = ControlContract(episode=EpisodeProtocol(control_hz=rate_hz, grasp_steps=steps, lift_steps=0,
                                                               hold_s=0.0))
            result = Runner(timed, spec, ClosePolicy(spec, contract, close_steps=steps), RunConfig(contract=contract)).run()
    finally:
        if fake is not None:
            fake.stop()
    periods = np.array(result.periods[1:] or [0.0])  # the first period includes start-up
    nominal = 1.0 / rate_hz
    return {"hand": hand, "backend": "sim" if hand == "sim" else "pty fake", "steps": result.steps,
            "rate_hz": rate_hz, "ok": result.ok, "reason": result.reason,
            "mean_period_ms": round(1e3 * float(periods.mean()), 3),
            "p99_jitter_ms": round(1e3 * float(np.percentile(np.abs(periods - nominal), 99)), 3),
            "max_period_ms": round(1e3 * float(periods.max()), 3),
            "overruns": result.overruns, "bus_errors": result.bus_errors,
            "mean_read_ms": _ms(timed.reads), "mean_write_ms": _ms(timed.writes)}


def _ms(values: list[float]) -> float:
    return round(1e3 * float(np.mean(values)), 3) if values else 0.0
