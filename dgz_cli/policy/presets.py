"""MAGCN architecture configuration and named presets.

Input and output sizes are not here: they come from the control contract
(:class:`dgz_cli.spec.contract.ControlContract`) the network is built for.

``paper`` follows Supp. "Policy Architecture (MAGCN)": 10 GCN layers (128, then 256 ×9), ReLU + LayerNorm,
physical MLP 27→32→d_p with LeakyReLU, global MLP 16→256 LeakyReLU, wrist/node heads 128 LeakyReLU,
value head 128 ReLU. d_p is not given in the paper; we use 32 (= the hidden size of φ_p).

``compact`` was chosen by measurement (see the comment above ``PRESETS``).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, field_validator

from dgz_cli.spec.models import N_FEATURES


class MagcnConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    phys_dim: int = Field(N_FEATURES, gt=0, description="physical feature size (27)")
    phys_hidden: int = Field(32, gt=0, description="hidden size of the physical encoder φ_p")
    phys_out: int = Field(32, gt=0, description="physical embedding size d_p")
    gcn_widths: tuple[int, ...] = Field((128,) + (256,) * 9, description="output width of each GCN layer (L = len)")
    global_hidden: int = Field(256, gt=0, description="global embedding size (φ_g: Linear + LeakyReLU)")
    head_hidden: int = Field(128, gt=0, description="hidden size of the wrist and node action heads")
    value_hidden: int = Field(128, gt=0, description="hidden size of the value head")
    init_log_std: float = Field(-0.5, description="initial log-std of the Gaussian policy (std ≈ 0.61)")
    use_physical: bool = Field(True, description="ablation: False drops E_p (no φ_p parameters)")
    early_fusion: bool = Field(False, description="ablation: concatenate E_p only at the first GCN layer")
    use_mask: bool = Field(True, description="ablation: False feeds zeros instead of the activation mask")
    log_std_per_type: bool = Field(False, description="one exploration log-std per (node type, primitive) "
                                   "instead of one per primitive shared by all nodes")
    critic_widths: tuple[int, ...] | None = Field(None, description="a separate critic: its own GCN trunk of these "
                                                  "widths (own φ_p and φ_g), so the value loss never moves the actor's "
                                                  "features; None = the value head on the actor's trunk (the paper)")

    @field_validator("gcn_widths", "critic_widths")
    @classmethod
    def _widths(cls, v: tuple[int, ...] | None) -> tuple[int, ...] | None:
        if v is not None and (not v or any(w <= 0 for w in v)):
            raise ValueError("GCN widths must be a non-empty tuple of positive ints")
        return v

    @property
    def num_layers(self) -> int:
        return len(self.gcn_widths)


# Measured on this 2-core CPU (torch 2.13, set_num_threads(2); another job held ~1 core, so absolute numbers
# are noisy): one forward + backward of a PPO-style loss + Adam step on 4096 graphs of N = 20 nodes, median of
# 4 round-robin runs (min in brackets), ms. MFLOP = flops_per_graph(cfg, 20).
#   paper 128+256×9   29.15 MFLOP  815k params   17313 (15126)
#   64×4               1.69 MFLOP  121k params    1370 (1004)   ≈12.6× cheaper
#   64×6               2.28 MFLOP  133k params    1395 (1242)   ≈12.4× cheaper   ← compact
#   96×6               3.92 MFLOP  179k params    2847 (2634)   ≈6.1×
#   128×4              4.12 MFLOP  193k params    3055 (2351)   ≈5.7×
# compact = 64×6 (2.28 MFLOP, 133k params): 6 layers let the wrist node see every fingertip of every shipped
# hand (max wrist→tip depth is 5, Shadow), at the price of 64×4 within noise. Heads keep the paper's sizes.
# Batch-1 forward (runtime), median: paper 1.23 ms, compact 0.46 ms with 1 thread; with 2 threads on the
# shared CPU 5.9 ms / 0.46 ms (p90 29 ms / 4.9 ms, OpenMP spin-waits): use 1 thread for single-graph inference.
# torch.compile (inductor, default mode): paper train step 15.7 → 13.3 s but 47 s to compile; compact no gain
# (2.7 → 2.9 s, 53 s to compile); batch-1 forward 2-4× faster after a ~13 s recompile for the new batch
# size. Not used by default.
PRESETS: dict[str, MagcnConfig] = {
    "paper": MagcnConfig(),
    "compact": MagcnConfig(gcn_widths=(64,) * 6),
}


def get_preset(name: str) -> MagcnConfig:
    try:
        return PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown MAGCN preset {name!r}; choose from {sorted(PRESETS)}") from None
