"""The HandSpec contract. This package imports nothing else of dgz."""
