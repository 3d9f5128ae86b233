"""Figures of an onboarded hand (the morphology-aligned graph over the kinematic skeleton)."""

from dgz_cli.viz.show import graph_table_rows, render_png

__all__ = ["graph_table_rows", "render_png"]
