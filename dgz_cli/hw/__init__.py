"""Hand drivers: one interface (:class:`dgz_cli.hw.driver.HandDriver`), one implementation per wire protocol;
arm interfaces for the wrist command (:mod:`dgz_cli.hw.arm`, :mod:`dgz_cli.hw.piper`).

Imports only :mod:`dgz_cli.spec` (never sim/policy/onboard). Per-hand facts live in ``hands/*.yaml``,
per-arm facts in ``arms/*.yaml``.
"""
