"""Simulated rate tables: the mechanics as a World device, served as a Modbus or ASCII controller."""

from .mechanics import CommandRejected, TableMechanics
from .modbus_server import ModbusTableServer, serve_modbus_table

__all__ = ["CommandRejected", "ModbusTableServer", "TableMechanics", "serve_modbus_table"]
