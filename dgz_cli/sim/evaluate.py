"""Evaluation protocol: every (hand, object) pair × trials episodes, success per episode.

Slots are filled with (hand, object) pairs; each slot runs ``trials`` consecutive episodes with
its own seeded randomization (hand pose, object orientation). Returns per-episode records, which also
carry the closing onset (:func:`closing_command`): the first control step at which the hand's fingers are
commanded to close, and the palm centre's distance to the object there (measured on the state the policy
acted on; no extra physics).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dgz_cli.sim import observe
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.hardware_view import HardwareView
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import ObjectModel
from dgz_cli.spec.models import NODE_TYPES, PRIMITIVES, HandSpec

# The hand closes (closing onset) at the first control step where its mean FLEX command, normalized, over its
# FLEX-active finger nodes exceeds this (:func:`closing_command`): half the full closing speed, so that a learned
# residual's small positive FLEX mean during the approach is not read as closing.
CLOSING_ONSET_FLEX = 0.5


def run_episodes(pairs: list[tuple[HandSpec, ObjectModel]], make_policy: Callable[[GraspEnv], object], trials: int,
                 cfg: EnvConfig = EnvConfig(), seed: int = 0, asset_root: str | None = None, threads: int = 2,
                 progress: Callable[[int, int], None] | None = None, view: HardwareView | None = None) -> list[dict]:
    """Run ``trials`` episodes on every pair; ``make_policy(env)`` returns an object with
    ``act(obs) -> action`` and ``reset(mask)``. Records: hand, object, trial, success, return_, r_*, the
    env's episode statistics, and the closing onset: ``closing_onset_step`` (control step, 0-based),
    ``closing_onset_distance_m`` (palm centre → nearest point of the object's surface cloud) and
    ``closing_onset_center_distance_m`` (palm centre → object centre, the distance ``approach_distance``
    sets at reset), all None when the hand never closed (:func:`closing_command`).
    ``view``: the hardware perturbations the policy observes under (a distilled student's; None = none)."""
    env = make_env(pairs, cfg, seed=seed, asset_root=asset_root, threads=threads, view=view)
    policy = make_policy(env)
    obs = env.reset(seed)
    policy.reset(None)
    done_count = np.zeros(env.B, dtype=np.int64)
    onset_step = np.full(env.B, -1, dtype=np.int64)  # -1: not closed yet in this episode
    onset_surface, onset_center = np.full(env.B, np.nan), np.full(env.B, np.nan)
    records: list[dict] = []
    total = trials * env.B
    while (done_count < trials).any():
        action = policy.act(obs)
        new = (onset_step < 0) & (closing_command(env, obs, action) > CLOSING_ONSET_FLEX)
        if new.any():  # the state the policy acted on (what obs was built from); read only at onsets
            surface, center = palm_object_distance(env)
            onset_step[new], onset_surface[new], onset_center[new] = env.t[new], surface[new], center[new]
        obs, _, _, _, info = env.step(action)
        finished = np.zeros(env.B, bool)
        for b, ep in info["episode"].items():
            finished[b] = True
            if done_count[b] < trials:
                closed = bool(onset_step[b] >= 0)
                records.append(dict(ep, trial=int(done_count[b]),
                                    closing_onset_step=int(onset_step[b]) if closed else None,
                                    closing_onset_distance_m=float(onset_surface[b]) if closed else None,
                                    closing_onset_center_distance_m=float(onset_center[b]) if closed else None))
            done_count[b] += 1
            onset_step[b], onset_surface[b], onset_center[b] = -1, np.nan, np.nan
        if finished.any():
            policy.reset(finished)
            if progress is not None:
                progress(min(total, int(np.minimum(done_count, trials).sum())), total)
    env.close()
    return records


def closing_command(env: GraspEnv, obs: dict[str, np.ndarray], action: np.ndarray) -> np.ndarray:
    """(B,) the hand's closing command at this step: the mean, over its FLEX-active finger nodes (activation
    mask FLEX = 1, not the wrist node, not padding), of the normalized FLEX command the env applies: the
    policy's ``action`` (B, action_dim) through the contract's composition (residual gains, closing prior)
    and the [-1, 1] clip, on the observation ``obs`` the action was chosen on, as
    :meth:`GraspEnv.apply_action` does. In the contract's ``joint`` action mode (raw joint increments, the
    w/o-primitives ablation) a node's FLEX command is the sign-corrected mean increment of its FLEX joints.
    0 for a hand without FLEX-active finger nodes."""
    contract = env.cfg.contract
    act = contract.action
    a = np.nan_to_num(np.asarray(action, dtype=np.float64))
    a = np.clip(contract.compose(a, obs["nodes"], obs["global"], env.closing, obs["node_valid"]), -1.0, 1.0)
    B, N = obs["node_valid"].shape
    fingers = a[:, act.wrist_dim:].reshape(B, N, act.n_prim)
    k = PRIMITIVES.index("FLEX")
    if act.mode == "primitive":
        flex = fingers[..., k]
    else:
        rows = np.broadcast_to(np.arange(B)[:, None], env.joint_node.shape)
        is_flex = (env.joint_prim == k) & (env.joint_sign != 0)  # padded joints have sign 0
        inc = np.where(is_flex, env.joint_sign * fingers[rows, env.joint_node, env.joint_slot], 0.0)
        total, count = np.zeros((B, N)), np.zeros((B, N))
        np.add.at(total, (rows, env.joint_node), inc)
        np.add.at(count, (rows, env.joint_node), is_flex)
        flex = total / np.maximum(count, 1.0)
    # the nodes the closing prior closes: FLEX-active (primitive mode) or with a FLEX joint (joint mode)
    active = (np.abs(env.closing).sum(-1) > 0) & obs["node_valid"] & (env.node_type[..., NODE_TYPES.index("wrist")] == 0)
    return (flex * active).sum(-1) / np.maximum(active.sum(-1), 1)


def palm_object_distance(env: GraspEnv) -> tuple[np.ndarray, np.ndarray]:
    """The palm centre's distances to the object in the env's current state (:meth:`GraspEnv.state`), m:
    (B,) to the nearest point of the object's surface cloud (``contract.observation.point_cloud`` points, the
    cloud of the observation's node → surface vectors; approximate to its spacing) and (B,) to the object
    centre (the cloud's centroid)."""
    st = env.state()
    palm = st["palm_pos"]
    d = observe.nearest_surface(palm[:, None], st["obj_pos"], st["obj_rot"], env.cloud, env.cloud_pre)[:, 0]
    center = env.cloud_centroid(st["obj_pos"], st["obj_rot"])
    return np.linalg.norm(d, axis=-1), np.linalg.norm(center - palm, axis=-1)


def make_env(pairs: list[tuple[HandSpec, ObjectModel]], cfg: EnvConfig, *, view: HardwareView | None = None,
             **kwargs) -> GraspEnv:
    """A :class:`GraspEnv`, or under an active hardware ``view`` a
    :class:`~dgz_cli.sim.hardware.HardwareViewEnv` (the observation a real hand and camera give). Evaluation
    and deploy run the full protocol: a training-only ``early_stop``, ``target_noise`` and ``dynamics_noise`` are
    turned off."""
    if cfg.early_stop or cfg.target_noise or cfg.dynamics_noise:
        cfg = cfg.model_copy(update=dict(early_stop=False, target_noise=0.0, dynamics_noise=0.0))
    if view is not None and view.active:
        from dgz_cli.sim.hardware import HardwareViewEnv

        return HardwareViewEnv(pairs, cfg, view, **kwargs)
    return GraspEnv(pairs, cfg, **kwargs)


FAILURE_CLASSES = ("never touched", "pushed away", "not lifted", "dropped during hold", "unstable")
PUSHED = 0.05  # m: an object displaced this much during the grasp phase was pushed, not grasped
GRASPXL_RISE = 0.1  # m: GraspXL's success criterion (rise at the end of the lift), a secondary column


def failure_class(record: dict, lift_height: float, success_fraction: float) -> str | None:
    """Why an episode failed (None if it succeeded): the paper's failure-case analysis, from the episode
    record of :class:`~dgz_cli.sim.env.GraspEnv`. Checked in this order: unstable (MuJoCo), never touched
    (no hand-object contact), pushed away (the object moved > 5 cm during the grasp phase, or the episode
    ended on the push limit) and not lifted (it did not follow the lift to success_fraction × lift_height),
    dropped during hold (it was up at the end of the lift but fell during the hold)."""
    if record["success"]:
        return None
    if record["unstable"]:
        return "unstable"
    if not record["touched"]:
        return "never touched"
    if record["rise_lift_end"] < success_fraction * lift_height:
        return "pushed away" if record.get("pushed") or record["max_push"] > PUSHED else "not lifted"
    return "dropped during hold"


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def summarize(records: list[dict], lift_height: float = 0.5, success_fraction: float = 0.8) -> dict:
    """Success rate per hand and per (hand, object), the failure classes of the failed episodes, the
    GraspXL criterion (rise ≥ 0.1 m at the end of the lift) as a secondary rate, and the closing onset:
    ``closing_onset_distance_m`` (palm centre → object surface), ``closing_onset_center_distance_m``
    (→ object centre) and ``closing_onset_step``, each the mean over the episodes in which the hand closed
    (``closed_episodes`` of them; None when it never closed); per object, its onset distance likewise."""
    out: dict[str, dict] = {}
    for r in records:
        h = out.setdefault(r["hand"], {"episodes": 0, "successes": 0, "graspxl": 0, "objects": {},
                                       "failures": dict.fromkeys(FAILURE_CLASSES, 0), "onset": []})
        h["episodes"] += 1
        h["successes"] += int(r["success"])
        h["graspxl"] += int(r["rise_lift_end"] >= GRASPXL_RISE)
        o = h["objects"].setdefault(r["object"], {"s": 0, "n": 0, "failures": dict.fromkeys(FAILURE_CLASSES, 0),
                                                  "onset": []})
        o["s"] += int(r["success"])
        o["n"] += 1
        if r.get("closing_onset_step") is not None:
            onset = (r["closing_onset_distance_m"], r["closing_onset_center_distance_m"], r["closing_onset_step"])
            h["onset"].append(onset)
            o["onset"].append(onset)
        why = failure_class(r, lift_height, success_fraction)
        if why is not None:
            h["failures"][why] += 1
            o["failures"][why] += 1
    for h in out.values():
        h["success_rate"] = h["successes"] / max(1, h["episodes"])
        h["graspxl_success_rate"] = h.pop("graspxl") / max(1, h["episodes"])
        onset = h.pop("onset")
        h["closing_onset_distance_m"] = _mean([x[0] for x in onset])
        h["closing_onset_center_distance_m"] = _mean([x[1] for x in onset])
        h["closing_onset_step"] = _mean([x[2] for x in onset])
        h["closed_episodes"] = len(onset)
        h["objects"] = {k: {"success_rate": o["s"] / o["n"], "trials": o["n"], "failures": o["failures"],
                            "closing_onset_distance_m": _mean([x[0] for x in o["onset"]])}
                        for k, o in sorted(h["objects"].items())}
    return out


# What `dgz eval --json` reports per hand (from summarize), and its per-episode `--csv` columns (csv_row).
REPORT_FIELDS = ("success_rate", "episodes", "failures", "graspxl_success_rate", "closing_onset_distance_m",
                 "closing_onset_center_distance_m", "closing_onset_step", "closed_episodes", "objects")
CSV_COLUMNS = ("hand", "object", "trial", "success", "failure", "max_rise_m", "return", "closing_onset_step",
               "closing_onset_distance_m", "closing_onset_center_distance_m")


def hand_reports(summary: dict) -> dict[str, dict]:
    """The ``hands`` section of `dgz eval --json`: :data:`REPORT_FIELDS` of every hand of :func:`summarize`."""
    return {name: {k: h[k] for k in REPORT_FIELDS} for name, h in summary.items()}


def csv_row(record: dict, lift_height: float = 0.5, success_fraction: float = 0.8) -> list[str]:
    """One episode record as the :data:`CSV_COLUMNS` cells (an empty cell: no failure, or the hand never closed)."""
    why = failure_class(record, lift_height, success_fraction)
    onset = record.get("closing_onset_step")

    def metres(key: str) -> str:
        return "" if onset is None else f"{record[key]:.4f}"

    return [record["hand"], record["object"], str(record["trial"]), str(int(record["success"])), why or "",
            f"{record['max_rise']:.4f}", f"{record['return_']:.3f}", "" if onset is None else str(onset),
            metres("closing_onset_distance_m"), metres("closing_onset_center_distance_m")]
