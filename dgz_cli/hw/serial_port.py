"""Open a serial port exclusively (pyserial) and turn OS failures into errors that say what to try."""

from __future__ import annotations

import errno

from dgz_cli.hw.errors import Disconnected, HardwareError

try:  # pyserial's flush/reset calls raise termios.error (not an OSError) when the device vanished
    import termios

    IO_ERRORS: tuple[type[BaseException], ...] = (OSError, termios.error)
except ImportError:  # pragma: no cover - non-POSIX
    IO_ERRORS = (OSError,)

PORT_HINT = "list adapters with `ls -l /dev/serial/by-id/` and prefer those stable paths"


def open_serial(port: str, baudrate: int, timeout: float, bytesize: int = 8, parity: str = "N", stopbits: int = 1):
    """A ``serial.Serial`` opened exclusively; ``timeout`` bounds every ``read(n)`` call (seconds)."""
    try:
        import serial
    except ImportError:  # pragma: no cover - pyserial is a dependency
        raise HardwareError("pyserial is not installed", "pip install 'pyserial>=3.5'") from None
    try:
        return serial.Serial(port, baudrate=baudrate, bytesize=bytesize, parity=parity, stopbits=stopbits,
                             timeout=timeout, write_timeout=max(timeout, 0.2), exclusive=True)
    except serial.SerialException as exc:
        code = getattr(exc, "errno", None)
        text = str(exc)
        if code == errno.ENOENT or "No such file" in text:
            raise HardwareError(f"{port}: no such serial port", f"is the hand plugged in? {PORT_HINT}") from None
        if code == errno.EACCES or "Permission denied" in text:
            raise HardwareError(f"{port}: permission denied",
                                "add yourself to the 'dialout' group (sudo usermod -aG dialout $USER) "
                                "and log in again") from None
        if code == errno.EAGAIN or "exclusively lock" in text:
            raise HardwareError(f"{port}: port is in use by another program",
                                "close the other program (another dgz, a vendor GUI, ModemManager) and retry") from None
        raise HardwareError(f"{port}: cannot open serial port: {text}", PORT_HINT) from None


def io_error(port: str, exc: BaseException) -> Disconnected:
    return Disconnected(f"{port}: serial port failed ({' '.join(str(exc).split())})",
                        "check the USB cable and the adapter's power, then reconnect")
