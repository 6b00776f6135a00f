"""The station entry of a Watlow F4 chamber on Modbus TCP or RTU (`driver = "watlow-f4"`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.devices import DriverSpec, Key, register_driver
from bench.streams import Column, StreamSchema, declare

#: the chamber's stream: its temperatures at every link check (the station's health rows)
CHAMBER_STREAM = declare(StreamSchema("chamber", "chamber", (
    Column("t_s", "s", quantity="time t"),
    Column("air_degc", "degC", quantity="chamber air temperature"),
    Column("part_degc", "degC", quantity="case (part thermocouple) temperature"),
)))


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .watlow_f4_driver import WatlowF4Chamber

    if cfg.get("serial_port"):
        chamber = WatlowF4Chamber.rtu(cfg["serial_port"], device_id=cfg["device_id"], timeout_s=cfg["timeout_s"])
    else:
        chamber = WatlowF4Chamber(cfg["host"], cfg["port"], device_id=cfg["device_id"], timeout_s=cfg["timeout_s"])
    chamber.connect()
    return chamber


def _health(device: Any, since: Any = None) -> np.ndarray:
    """A sign of life (LinkLostError when the controller is gone) and the chamber stream's row."""
    return np.array([[device.air_c(), device.part_c()]])


SPEC = register_driver(
    DriverSpec(
        name="watlow-f4",
        role="chamber",
        part="chamber-to-ambient",
        keys={
            "driver": Key(str, required=True),
            "host": Key(str, "127.0.0.1", doc="Modbus TCP host"),
            "port": Key(int, 502, 1, 65535, doc="Modbus TCP port"),
            "serial_port": Key(str, "", doc="RTU on a serial port instead of TCP"),
            "device_id": Key(int, 1, 0, 247, doc="Modbus unit id"),
            "timeout_s": Key(float, 1.0, 0.01, 60.0, unit="s", doc="reply timeout"),
            "min_degc": Key(float, -70.0, -100.0, 200.0, unit="degC", doc="simulator: lowest set point"),
            "max_degc": Key(float, 180.0, -100.0, 300.0, unit="degC", doc="simulator: highest set point"),
            "ramp_degc_per_min": Key(float, 2.0, 0.01, 100.0, unit="degC/min", doc="simulator: air ramp limit"),
            "case_tau_s": Key(float, 1200.0, 1.0, 1e6, unit="s",
                              doc="simulator: the unit case's thermal time constant behind the air"),
            "profiles": Key(bool, True, doc="simulator: the controller runs profiles (a ramp-rate step's ramp); "
                            "off: it answers the constant set-point registers only"),
            "resonator_tau_s": Key(float, 0.0, 0.0, 1e6, unit="s",
                                   doc="simulator: the resonator's thermal time constant behind the case "
                                       "(0: at the case's temperature)"),
        },
        build=_build,
        serve="simulators.chamber.watlow_f4_server:serve_station",
        health=_health,
        health_columns=CHAMBER_STREAM.names[1:],
        doc="temperature chamber, Watlow F4 controller on Modbus TCP or RTU",
    )
)
