"""MuJoCo grasping environment built from any HandSpec. Imports only ``dgz_cli.spec``."""
