"""dgz: DexGrasp-Zero — one graph policy for any dexterous hand."""

__version__ = "0.1.0"
