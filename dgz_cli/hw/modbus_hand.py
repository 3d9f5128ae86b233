"""Shared plumbing of the Modbus RTU hands (Inspire RH56, Revo2): port, master, identity errors."""

from __future__ import annotations

from dgz_cli.hw.config import HandConfig
from dgz_cli.hw.errors import BusTimeout, HardwareError, IdentityError
from dgz_cli.hw.jointmap import JointMapper
from dgz_cli.hw.modbus_rtu import ModbusMaster
from dgz_cli.hw.serial_driver import SerialHandDriver
from dgz_cli.hw.serial_port import open_serial
from dgz_cli.spec.models import HandSpec


class ModbusHand(SerialHandDriver):
    wiring_hint = "check power, the RS485 A/B wiring, the slave id and baud rate in the hand file"

    def __init__(self, cfg: HandConfig, spec: HandSpec, port: str) -> None:
        super().__init__(spec, port)
        self.cfg = cfg
        self.slave = int(cfg.slave_id)
        self.settings = cfg.settings()
        self.ser = None
        self.bus: ModbusMaster | None = None
        self.mapper: JointMapper | None = None

    def _open(self) -> None:
        p = self.cfg.port
        self.ser = open_serial(self.port, p.baudrate, p.timeout, p.bytesize, p.parity, p.stopbits)
        self.bus = ModbusMaster(self.ser, self.port, p.baudrate)

    def _identify(self, what: str, call):
        """Run an identity read; a silent or garbled device becomes an IdentityError that says what to try."""
        try:
            return call()
        except BusTimeout:
            raise IdentityError(f"{self.port}: no reply from {self.cfg.name} (Modbus slave {self.slave}, "
                                f"{self.cfg.port.baudrate} baud) while reading {what}",
                                f"{self.wiring_hint}; is this the right port (ls -l /dev/serial/by-id/)?") from None
        except HardwareError as exc:
            raise IdentityError(f"{self.port}: {self.cfg.name} identity check failed reading {what}: {exc.message}",
                                exc.hint or self.wiring_hint) from None
