"""The station entry of the SCPI DAC/ADC front end (`driver = "scpi-frontend"`)."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, register_driver


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .driver import FrontEndLimits, ScpiFrontEnd

    fe = ScpiFrontEnd(
        cfg["resource"],
        clock=clock,
        limits=FrontEndLimits(max_amplitude_v=cfg["max_amplitude_v"]),
        timeout_s=cfg["timeout_s"],
    )
    fe.connect()
    return fe


def _health(fe: Any, since: Any = None) -> None:
    fe.probe()  # the tagged *IDN?: a query that proves the instrument answers


SPEC = register_driver(
    DriverSpec(
        name="scpi-frontend",
        role="frontend",
        part="outputs-off",
        keys={
            "driver": Key(str, required=True),
            "resource": Key(str, "", doc="VISA resource name"),
            "max_amplitude_v": Key(float, 5.0, 0.0, 10.0, doc="drive amplitude limit", unit="V"),
            "timeout_s": Key(float, 2.0, 0.05, 60.0, doc="wall time allowed for a reply", unit="s"),
        },
        build=_build,
        serve="simulators.frontend:serve_station",
        health=_health,
        doc="DAC/ADC front end, SCPI over VISA",
    )
)
