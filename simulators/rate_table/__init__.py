"""Simulated rate tables: the mechanics as a World device, served as a Modbus or ASCII controller."""

from .ascii_server import AsciiTableServer, serve_ascii_table
from .mechanics import CommandRejected, TableMechanics
from .modbus_server import ModbusTableServer, serve_modbus_table

__all__ = [
    "AsciiTableServer",
    "CommandRejected",
    "ModbusTableServer",
    "TableMechanics",
    "serve_ascii_table",
    "serve_modbus_table",
]
