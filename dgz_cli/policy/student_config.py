"""The student's memory configuration (torch-free, so manifests and ``--help`` load without torch); the
network is :class:`dgz_cli.policy.student.StudentMAGCN`."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class StudentConfig(BaseModel):
    """The student's memory (the MAGCN backbone's sizes are the teacher's :class:`MagcnConfig`)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    history: int = Field(5, ge=1, le=64, description="steps the LSTM sees (the current one included)")
    lstm_hidden: int = Field(256, ge=1, le=4096, description="hidden size of the single-layer LSTM")
