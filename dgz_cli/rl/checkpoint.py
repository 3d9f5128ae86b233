"""Checkpoints: weights as safetensors (no pickle, so loading never runs code) + a typed YAML manifest.

A checkpoint folder holds ``checkpoint.yaml`` (:class:`CheckpointMeta`: the run's configs, the control
contract, the iteration, training hands with their spec hashes, git revision, the name and sha256 of the
weights file) and the weights file it names. Saving writes the weights under a new name first, then
switches ``checkpoint.yaml`` with one atomic rename: a kill at any moment leaves either the old or the
new checkpoint whole. Loading checks the weights' sha256 against the manifest.

Format history: 1 (untyped dict, weights always ``model.safetensors``) is migrated on load by
:func:`migrate_v1`; the two policies shipped before format 2 are format 1. Format 3 (issue 12) is format 2
plus a ``student`` section (:class:`~dgz_cli.rl.distill_config.StudentMeta`): a distilled student, whose
observation layout has no privileged block and whose forward also reads a history of the last steps
(:mod:`dgz_cli.policy.student`); teachers are still written as format 2, so older readers keep reading them.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from dgz_cli.policy.presets import MagcnConfig
from dgz_cli.rl.config import TrainConfig
from dgz_cli.rl.distill_config import StudentMeta
from dgz_cli.spec.contract import ActionLayout, ControlContract, EpisodeProtocol, ObservationLayout
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes

FORMAT = 2
STUDENT_FORMAT = 3
META_FILE = "checkpoint.yaml"
MAX_META_BYTES = 4 << 20
MAX_WEIGHTS_BYTES = 2 << 30


class NormalizerState(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    mean: float = Field(allow_inf_nan=False)
    var: float = Field(ge=0, allow_inf_nan=False)
    count: float = Field(gt=0, allow_inf_nan=False)


class CheckpointMeta(BaseModel):
    """Everything needed to rebuild, evaluate, deploy or resume a policy, typed and versioned."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    format: Literal[2, 3] = FORMAT
    iteration: int = Field(ge=0)
    weights: str = Field(pattern=r"^[A-Za-z0-9_.-]+\.safetensors$", description="weights file in the same folder")
    weights_sha256: str | None = Field(None, pattern=r"^[0-9a-f]{64}$", description="None only for migrated format 1")
    train: TrainConfig
    model: MagcnConfig
    env: EnvConfig
    training_hands: dict[str, str] = Field(description="hand name → sha256 of its spec file at training time")
    git_revision: str | None = None
    learning_rate: float = Field(gt=0, allow_inf_nan=False)
    reward_normalizer: NormalizerState | None = None
    last: dict[str, float | int | None] | None = Field(None, description="the last history row")
    warm_start: dict[str, Any] | None = Field(None, description="behaviour-cloning statistics, if warm-started")
    pair_success: dict[str, float] | None = Field(None, description="success EMA per 'hand/object' pair (prioritised "
                                                  "sampling's state)")
    student: StudentMeta | None = Field(None, description="format 3: a distilled student (``train`` is then its "
                                        "teacher's run config, ``model`` its backbone's)")

    @model_validator(mode="after")
    def _student_format(self) -> "CheckpointMeta":
        if (self.format == STUDENT_FORMAT) != (self.student is not None):
            raise ValueError("format 3 marks a student checkpoint: it needs the 'student' section, and only it has one")
        if self.student is not None and self.env.contract.privileged_inputs:
            raise ValueError(f"a student observes no privileged inputs; its layout has "
                             f"{list(self.env.contract.privileged_inputs)}")
        return self

    @property
    def contract(self) -> ControlContract:
        return self.env.contract

    @property
    def privileged_inputs(self) -> tuple[str, ...]:
        return self.env.contract.privileged_inputs


V1_KEYS = frozenset({"dgz_checkpoint", "iteration", "train", "policy", "ppo", "env", "training_hands", "git_revision",
                     "learning_rate", "reward_normalizer", "last", "warm_start", "privileged_inputs"})


def migrate_v1(meta: dict) -> dict:
    """Format 1 (flat env dict, model sizes in the model config) → format 2 fields."""
    unknown = sorted(set(meta) - V1_KEYS)
    if unknown:
        raise ValueError(f"unknown field(s) {unknown} in a format-1 manifest")
    env = dict(meta.get("env") or {})
    model = dict((meta.get("policy") or {}).get("model") or {})
    contract = ControlContract(
        observation=ObservationLayout(distance_clip=env.pop("distance_clip", 0.3), force_scale=env.pop("force_scale", 10.0),
                                      point_cloud=env.pop("point_cloud", 256)),
        action=ActionLayout(mode=env.pop("action_mode", "primitive"), finger_scale=env.pop("finger_action_scale", 0.015),
                            wrist_scale=env.pop("wrist_action_scale", 0.01),
                            wrist_dim=model.pop("wrist_dim", 6), n_prim=model.pop("n_prim", 3)),
        episode=EpisodeProtocol(**{k: env.pop(k) for k in list(env) if k in EpisodeProtocol.model_fields}))
    dims = (model.pop("node_dim", 23), model.pop("global_dim", 16))
    if dims != (contract.observation.node_dim, contract.observation.global_dim):
        raise ValueError(f"format-1 model expects {dims[0]}/{dims[1]} node/global features; format 1 always had 23/16")
    declared = meta.get("privileged_inputs", ["contact", "force"])
    if declared is None or sorted(declared) != list(contract.privileged_inputs):
        raise ValueError(f"field 'privileged_inputs': {declared!r} disagrees with the observation layout "
                         f"(which holds {list(contract.privileged_inputs)})")
    train = dict(meta.get("train") or {})
    train["ppo"] = meta.get("ppo") or {}
    return dict(format=FORMAT, iteration=meta.get("iteration"), weights="model.safetensors", weights_sha256=None,
                train=train, model=model, env=dict(env, contract=json.loads(contract.model_dump_json(by_alias=True))),
                training_hands=meta.get("training_hands"), git_revision=meta.get("git_revision"),
                learning_rate=meta.get("learning_rate"), reward_normalizer=meta.get("reward_normalizer"),
                last=meta.get("last"), warm_start=meta.get("warm_start"))


def git_revision(repo: Path | None = None) -> str | None:
    """HEAD of the dgz checkout, with ``-dirty`` when tracked files have uncommitted changes; None outside git."""
    cwd = repo or Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=5)
        if out.returncode != 0 or not out.stdout.strip():
            return None
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() + ("-dirty" if dirty.returncode == 0 and dirty.stdout.strip() else "")


def resolve_checkpoint(ref: str) -> Path | None:
    """A checkpoint folder path, or the name of a shipped policy (``policies/`` of the checkout or the wheel's
    package data); None when neither exists."""
    from dgz_cli.spec.catalog import policies_dir

    path = Path(ref)
    if path.is_dir():
        return path
    if "/" not in ref and ref not in (".", "..") and (policies_dir() / ref).is_dir():
        return policies_dir() / ref
    return None


def spec_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _where(directory: Path) -> Path:
    return Path(directory) / META_FILE


def read_meta(directory: Path) -> CheckpointMeta:
    """The validated manifest of a checkpoint folder (format 1 is migrated). One-line errors name the file."""
    meta_file = _where(directory)
    if not meta_file.is_file():
        raise DgzError(f"{directory}: not a dgz checkpoint (no {META_FILE})",
                       "point --policy at a folder written by `dgz train` (e.g. runs/NAME or policies/NAME)")
    if meta_file.stat().st_size > MAX_META_BYTES:
        raise DgzError(f"{meta_file}: {meta_file.stat().st_size} bytes, too large for a checkpoint manifest",
                       "restore the file from the run directory")
    try:
        raw = yaml.safe_load(meta_file.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise DgzError(f"{meta_file}: malformed YAML ({' '.join(str(exc).split())})",
                       "restore the file from the run directory") from None
    if not isinstance(raw, dict):
        raise DgzError(f"{meta_file}: not a checkpoint manifest (a mapping is expected)", "is this a dgz checkpoint?")
    try:
        if raw.get("dgz_checkpoint") == 1:
            raw = migrate_v1(raw)
        return CheckpointMeta.model_validate(raw)
    except (ValidationError, ValueError, TypeError) as exc:
        if isinstance(exc, ValidationError):
            e = exc.errors()[0]
            msg = f"field '{'.'.join(map(str, e['loc']))}': {e['msg']}"
        else:
            msg = " ".join(str(exc).split())
        raise DgzError(f"{meta_file}: {msg}", "the manifest is damaged or from an unknown dgz version; "
                                              "use a checkpoint written by this dgz") from None


def save(directory: Path, tensors: dict, meta: CheckpointMeta) -> CheckpointMeta:
    """Write ``tensors`` (name → torch.Tensor) and the manifest; returns the manifest as written (with the
    weights file name and hash filled in). Earlier weights files of the folder are removed afterwards."""
    from safetensors.torch import save as to_bytes

    directory = Path(directory)
    blob = to_bytes({k: v.detach().contiguous().cpu() for k, v in tensors.items()})
    name = f"model-{meta.iteration:07d}.safetensors"
    meta = meta.model_copy(update=dict(weights=name, weights_sha256=hashlib.sha256(blob).hexdigest()))
    atomic_write_bytes(directory / name, blob)
    text = yaml.safe_dump(json.loads(meta.model_dump_json(by_alias=True)), sort_keys=False)
    atomic_write_bytes(_where(directory), text.encode())  # the switch
    for old in directory.glob("model*.safetensors"):
        if old.name != name:
            old.unlink(missing_ok=True)
    return meta


def load(directory: Path) -> tuple[dict, CheckpointMeta]:
    """(tensors, manifest). Never unpickles: safetensors + yaml.safe_load; the weights' hash is checked."""
    from safetensors import SafetensorError
    from safetensors.torch import load as from_bytes

    directory = Path(directory)
    meta = read_meta(directory)
    weights = directory / meta.weights
    if not weights.is_file():
        raise DgzError(f"{weights}: missing (named by {META_FILE})", "the checkpoint is incomplete; use an earlier one")
    if weights.stat().st_size > MAX_WEIGHTS_BYTES:
        raise DgzError(f"{weights}: {weights.stat().st_size} bytes, larger than any dgz policy", "use another checkpoint")
    blob = weights.read_bytes()
    if meta.weights_sha256 is not None and hashlib.sha256(blob).hexdigest() != meta.weights_sha256:
        raise DgzError(f"{weights}: sha256 differs from the one in {META_FILE}",
                       "the weights and the manifest do not belong together; use an earlier checkpoint")
    try:
        tensors = from_bytes(blob)
    except (SafetensorError, OSError, ValueError) as exc:
        raise DgzError(f"{weights}: unreadable weights ({' '.join(str(exc).split())})",
                       "the file is damaged; use an earlier checkpoint") from None
    return tensors, meta


class LoadedPolicy:
    """A checkpoint's MAGCN for evaluation and deployment: ``act`` (the Gaussian's mean) and ``sample``, on
    numpy observations laid out by ``meta.contract``, with one torch thread (batch inference next to
    physics or a bus). Actions are normalized (B, action_dim)."""

    def __init__(self, directory: Path) -> None:
        import torch

        from dgz_cli.policy.magcn import MAGCN

        self.directory = Path(directory)
        tensors, self.meta = load(self.directory)
        self.history = None  # a student's TokenHistory, sized on the first act
        if self.meta.student is not None:
            from dgz_cli.policy.student import StudentMAGCN

            self.model = StudentMAGCN(self.meta.model, self.meta.contract, self.meta.student.distill.student)
        else:
            self.model = MAGCN(self.meta.model, self.meta.contract)
        weights = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
        try:
            self.model.load_state_dict(weights)
        except RuntimeError as exc:
            raise DgzError(f"{self.directory}: weights do not match the checkpoint's model config "
                           f"({str(exc).splitlines()[0]})",
                           "the checkpoint is damaged or was written by another dgz version") from None
        bad = [k for k, v in weights.items() if not bool(torch.isfinite(v).all())]
        if bad:
            raise DgzError(f"{self.directory}: non-finite weights in {bad[0]} (and {len(bad) - 1} more)",
                           "the run diverged; use an earlier checkpoint")
        self.model.eval()
        self._torch = torch

    def reset(self, mask=None) -> None:
        """An episode starts where ``mask`` (B,) is True (everywhere when None; an evaluation loop calls this
        when episodes end, the deploy loop before its episode): a student forgets those histories. The
        MAGCN teacher is stateless."""
        if self.history is not None:
            self.history.reset(mask)

    def _inputs(self, obs: dict):
        """Observation tensors; for a student, this step's token is pushed and the history added."""
        from dgz_cli.policy.graph import to_tensors

        self._torch.set_num_threads(1)
        obs_t = to_tensors(obs)
        if self.meta.student is None:
            return obs_t
        from dgz_cli.policy.student import TokenHistory, student_obs, tokens

        b = obs_t["nodes"].shape[0]
        if self.history is None or self.history.buf.shape[0] != b:
            self.history = TokenHistory(b, self.meta.student.distill.student.history, self.model.token_dim)
        lay = self.meta.contract.observation
        tok = tokens(obs_t["nodes"].numpy(), obs_t["global"].numpy(), obs_t["node_valid"].numpy(), lay)
        return student_obs(obs_t, self.history.push(tok))

    def act(self, obs: dict):
        return self.model.act(self._inputs(obs)).numpy()

    def sample(self, obs: dict):
        return self.model.sample(self._inputs(obs))["action"].numpy()
