"""Hand drivers: one interface (:class:`dgz_cli.hw.driver.HandDriver`), one implementation per wire protocol.

Imports only :mod:`dgz_cli.spec` (never sim/policy/onboard). Per-hand facts live in ``hands/*.yaml``.
"""
