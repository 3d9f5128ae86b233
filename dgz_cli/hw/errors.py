"""Hardware errors. Each names the port (or field) and says what to try, like every :class:`DgzError`.

Transient errors (a lost or garbled reply) are counted by the runtime and stop it only when they repeat;
a device-reported fault or a vanished port stops it at once.
"""

from __future__ import annotations

from dgz_cli.spec.errors import DgzError


class HardwareError(DgzError):
    """Anything that went wrong talking to a hand."""


class BusTimeout(HardwareError):
    """No (complete) reply within the timeout. Transient."""


class BusCrcError(HardwareError):
    """A reply arrived with a bad checksum or garbled framing. Transient."""


class DeviceFault(HardwareError):
    """The device answered with an exception / error status: stop now."""


class Disconnected(HardwareError):
    """The port vanished (USB unplugged, adapter reset): stop now."""


class IdentityError(HardwareError):
    """The device on the port is not the hand the configuration describes (or does not answer at all)."""


class StaleFeedback(HardwareError):
    """Feedback frozen while the hand was being commanded to move."""


class ConfigError(HardwareError):
    """A hand file (dgz_cli/hw/hands/*.yaml) is invalid or does not match its HandSpec."""


TRANSIENT = (BusTimeout, BusCrcError)


class ImplausibleReading(HardwareError):
    """A joint reading that cannot be real (NaN/inf, or far outside the joint's range): stop now, name the joint."""
